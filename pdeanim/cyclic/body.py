"""Cut an elongated mesh into cross-section curves that a chain of PDE patches can interpolate.

The body frame comes from the principal axes (head to tail along the longest one, or set by head/tail
points); planes orthogonal to the axis slice the mesh, the outer loop of each slice is kept, oriented
counter-clockwise about the axis and resampled by arc length from the point where it crosses the lateral
half-line, so curve samples correspond from one slice to the next.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from trimesh import intersections

from ..errors import InputError, MeshInputError


@dataclass(frozen=True)
class BodyFrame:
    """Orthonormal body axes: axis (head to tail), lateral (side to side), up = axis x lateral.

    origin : (3,) float64 centroid of the vertices; x_min, x_max: extent of the mesh along the axis from it.
    """

    origin: np.ndarray
    axis: np.ndarray
    lateral: np.ndarray
    up: np.ndarray
    x_min: float
    x_max: float

    @property
    def length(self) -> float:
        """Extent of the mesh along the axis."""
        return self.x_max - self.x_min

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points to (N, 3) body coordinates (axial, lateral, up)."""
        return (np.asarray(points, dtype=np.float64) - self.origin) @ self.basis().T

    def basis(self) -> np.ndarray:
        """(3, 3) rows axis, lateral, up."""
        return np.stack([self.axis, self.lateral, self.up])

    def to_dict(self) -> dict:
        """JSON-able form (lists of floats)."""
        return {"origin": self.origin.tolist(), "axis": self.axis.tolist(), "lateral": self.lateral.tolist(),
                "up": self.up.tolist(), "x_min": self.x_min, "x_max": self.x_max}

    @staticmethod
    def from_dict(d: dict) -> BodyFrame:
        """Inverse of :meth:`to_dict`."""
        arr = {k: np.asarray(d[k], dtype=np.float64) for k in ("origin", "axis", "lateral", "up")}
        return BodyFrame(**arr, x_min=float(d["x_min"]), x_max=float(d["x_max"]))


@dataclass(frozen=True)
class BodyCurves:
    """Cross-section curves of a body: curves (K, P, 3) float64 world positions, stations (K,) axial
    coordinates of the slicing planes, loops (K,) int number of loops found in each slice."""

    curves: np.ndarray
    stations: np.ndarray
    loops: np.ndarray
    frame: BodyFrame


def _sign_fixed(vec: np.ndarray) -> np.ndarray:
    """A unit vector with its largest-magnitude component made positive (deterministic eigenvectors)."""
    vec = vec / np.linalg.norm(vec)
    return vec if vec[np.argmax(np.abs(vec))] > 0 else -vec


def _unit(vec: object, what: str) -> np.ndarray:
    arr = np.asarray(vec, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.isfinite(arr).all() or np.linalg.norm(arr) < 1e-12:
        raise InputError(f"{what} must be a non-zero 3-vector")
    return arr / np.linalg.norm(arr)


def body_frame(vertices: np.ndarray, *, head: object = None, tail: object = None, lateral: object = None,
               min_elongation: float = 1.2) -> BodyFrame:
    """Body axes of a mesh from its principal axes, oriented head to tail.

    vertices : (V, 3); head/tail: optional (3,) points near the head/tail (both: the axis is tail - head;
    one: picks which end of the principal axis is the head; none: the thicker end is the head);
    lateral: optional (3,) sideways direction (default: the principal direction of least spread).
    Raises InputError when the body is not elongated (longest extent < min_elongation x the next).
    """
    pts = np.asarray(vertices, dtype=np.float64)
    origin = pts.mean(axis=0)
    rel = pts - origin
    _, vecs = np.linalg.eigh(rel.T @ rel)  # ascending variance
    if head is not None and tail is not None:
        axis = _unit(np.asarray(tail, float) - np.asarray(head, float), "tail - head")
    else:
        axis = _sign_fixed(vecs[:, 2])
    x = rel @ axis
    perp = rel - np.outer(x, axis)
    ext_perp = np.ptp(perp @ np.linalg.svd(perp, full_matrices=False)[2][:2].T, axis=0).max()
    if np.ptp(x) < min_elongation * ext_perp:
        raise InputError(
            f"the mesh is not elongated enough to be cut into cross-sections (length {np.ptp(x):.4g}"
            f" vs width {ext_perp:.4g}); set head and tail points to choose the body axis"
        )
    if lateral is not None:
        lat = _unit(lateral, "lateral")
        lat = lat - axis * (lat @ axis)
        if np.linalg.norm(lat) < 1e-9:
            raise InputError("the lateral direction must not be parallel to the body axis")
        lat = lat / np.linalg.norm(lat)
    else:
        cov = perp.T @ perp
        w, v = np.linalg.eigh(cov + np.outer(axis, axis) * (np.trace(cov) + 1.0))
        lat = _sign_fixed(v[:, 0])
    if head is not None and tail is None:
        if (np.asarray(head, float) - origin) @ axis > 0:
            axis = -axis
    elif head is None and tail is not None:
        if (np.asarray(tail, float) - origin) @ axis < 0:
            axis = -axis
    elif head is None and tail is None and _tail_is_thicker(x, np.abs(rel @ lat)):
        axis = -axis
    up = np.cross(axis, lat)
    if lateral is None and up[np.argmax(np.abs(up))] < 0:  # prefer "up" along a positive world axis
        lat, up = -lat, -up
    x = rel @ axis
    return BodyFrame(origin, axis, lat, up, float(x.min()), float(x.max()))


def _tail_is_thicker(x: np.ndarray, width: np.ndarray) -> bool:
    """True when the vertices in the last quarter along x are on average wider than in the first quarter."""
    lo, hi = x.min(), x.max()
    q = 0.25 * (hi - lo)
    first, last = width[x <= lo + q], width[x >= hi - q]
    return bool(len(first) and len(last) and last.mean() > first.mean())


def chain_segments(segments: np.ndarray, tol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Join line segments (S, 2, 3) into closed loops and open chains of points (each (n, 3))."""
    if len(segments) == 0:
        return [], []
    pts = segments.reshape(-1, 3)
    pairs = cKDTree(pts).query_pairs(tol, output_type="ndarray")  # ends closer than tol are one point
    link = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(pts), len(pts)))
    _, node = connected_components(link, directed=False)
    first = np.full(node.max() + 1, len(pts))
    np.minimum.at(first, node, np.arange(len(pts)))
    node = node.reshape(-1, 2)
    node = node[node[:, 0] != node[:, 1]]
    adj: dict[int, list[int]] = {}
    for a, b in np.unique(np.sort(node, axis=1), axis=0).tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    seen: set[int] = set()
    loops, chains = [], []
    ends = [n for n, nb in adj.items() if len(nb) != 2]
    for start in ends + sorted(adj):
        if start in seen:
            continue
        path, prev, cur = [start], -1, start
        seen.add(start)
        while True:
            nxt = [n for n in adj[cur] if n != prev and n not in seen]
            if not nxt:
                closed = len(path) > 2 and start in adj[cur] and prev != start
                break
            prev, cur = cur, nxt[0]
            path.append(cur)
            seen.add(cur)
        (loops if closed else chains).append(pts[first[np.array(path)]])
    return loops, chains


def _area_2d(p: np.ndarray) -> float:
    """Signed shoelace area of a closed polygon (n, 2)."""
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def resample_loop(loop: np.ndarray, frame: BodyFrame, n_points: int) -> np.ndarray:
    """Resample a closed loop (n, 3) to (n_points, 3): counter-clockwise about the body axis, starting where
    it crosses the lateral half-line from its centroid, equally spaced in arc length."""
    loc = frame.to_local(loop)[:, 1:]
    if _area_2d(loc) < 0:
        loop, loc = loop[::-1], loc[::-1]
    q = loc - loc.mean(axis=0)
    nq = np.roll(q, -1, axis=0)
    cross = (q[:, 1] <= 0) & (nq[:, 1] > 0)
    frac = np.where(cross, -q[:, 1] / np.where(cross, nq[:, 1] - q[:, 1], 1.0), 0.0)
    xcut = q[:, 0] + frac * (nq[:, 0] - q[:, 0])
    cand = np.flatnonzero(cross & (xcut > 0))
    if len(cand):
        i = int(cand[np.argmax(xcut[cand])])
        start = loop[i] + frac[i] * (np.roll(loop, -1, axis=0)[i] - loop[i])
        ring = np.concatenate([[start], np.roll(loop, -(i + 1), axis=0), [start]])
    else:
        i = int(np.argmax(q[:, 0]))
        ring = np.concatenate([np.roll(loop, -i, axis=0), loop[i:i + 1]])
    seg = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if arc[-1] <= 0:
        raise InputError("a cross-section loop has zero length")
    target = np.arange(n_points) * (arc[-1] / n_points)
    return np.stack([np.interp(target, arc, ring[:, k]) for k in range(3)], axis=1)


def _slice_outer_loop(
    mesh: trimesh.Trimesh, frame: BodyFrame, x: float, tol: float
) -> tuple[np.ndarray | None, int]:
    """The outer loop of the mesh cut by the plane at axial coordinate x, and how many loops the cut has."""
    segs = intersections.mesh_plane(mesh, frame.axis, frame.origin + x * frame.axis)
    loops, chains = chain_segments(np.asarray(segs, dtype=np.float64), tol)
    if not loops and chains:  # an open mesh: close its longest chain
        loops = [max(chains, key=len)]
    loops = [lp for lp in loops if len(lp) >= 3]
    if not loops:
        return None, 0
    areas = [abs(_area_2d(frame.to_local(lp)[:, 1:])) for lp in loops]
    return loops[int(np.argmax(areas))], len(loops)


def _tip(vertices: np.ndarray, frame: BodyFrame, at_max: bool) -> np.ndarray:
    """The tip of the body at one end of the axis: the centroid of the vertices at the extreme (3,)."""
    x = frame.to_local(vertices)[:, 0]
    edge = x.max() if at_max else x.min()
    return vertices[np.abs(x - edge) <= 1e-6 * frame.length].mean(axis=0)


def cut_body(vertices: np.ndarray, faces: np.ndarray, frame: BodyFrame, n_curves: int, n_points: int,
             margin: float = 0.02, close_ends: bool = True) -> BodyCurves:
    """Slice the mesh at n_curves equally spaced stations along its axis.

    vertices (V, 3), faces (T, 3) -> BodyCurves with curves (n_curves, n_points, 3). With close_ends the first
    and last curves collapse to the head and tail tips (so the surface closes the body) and the stations span
    the whole length; otherwise they span margin .. 1 - margin of it.
    Raises InputError when a slice is empty or every slice has several loops.
    """
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshInputError("the mesh has no triangle faces to cut into cross-sections")
    verts = np.asarray(vertices, dtype=np.float64)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    tol = 1e-8 * max(frame.length, 1e-300)
    lo, hi = (0.0, 1.0) if close_ends else (margin, 1.0 - margin)
    stations = frame.x_min + frame.length * np.linspace(lo, hi, n_curves)
    inner = range(1, n_curves - 1) if close_ends else range(n_curves)
    curves, loops = [], []
    for k in inner:
        x = float(stations[k])
        loop, count = _slice_outer_loop(mesh, frame, x, tol)
        if loop is None:  # the plane may run along an edge: try once slightly off
            loop, count = _slice_outer_loop(mesh, frame, x + 1e-6 * frame.length, tol)
        if loop is None:
            raise InputError(
                f"cross-section {k} at {(x - frame.x_min) / frame.length:.0%} of the body length is "
                "empty: the mesh cannot be cut into closed cross-sections along its axis"
            )
        curves.append(resample_loop(loop, frame, n_points))
        loops.append(count)
    loops_arr = np.asarray(loops)
    if (loops_arr > 1).all():
        raise InputError("every cross-section has several separate loops: the mesh is not one elongated body")
    if close_ends:
        curves = [np.repeat(_tip(verts, frame, False)[None], n_points, 0), *curves,
                  np.repeat(_tip(verts, frame, True)[None], n_points, 0)]
        loops_arr = np.concatenate([[1], loops_arr, [1]])
    return BodyCurves(np.stack(curves), stations, loops_arr, frame)
