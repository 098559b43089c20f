"""Connectivity of a mesh for curve extraction: weld duplicated (seam) vertices by position, build edges.

Welding is for connectivity only: curves always carry the original vertex ids, and all copies of a welded
point end up next to each other on the same curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import MeshInputError

WELD_TOL = 1e-7  # welding tolerance, relative to the bounding-box diagonal
KNN_ISOLATED = 4  # neighbours that link vertices not referenced by any edge


@dataclass(frozen=True)
class WeldedGraph:
    """Welded points and their edges.

    weld : (V,) int64, welded point of every original vertex
    points : (P, 3) float64, position of every welded point
    edges : (E, 2) int64, unique undirected edges between welded points (i < j)
    faces : (T', 3) int64, non-degenerate faces in welded ids
    component : (P,) int64, connected component of every welded point (ordered by first vertex)
    knn : (E,) bool, edges added between unreferenced points (not from faces)
    """

    weld: np.ndarray
    points: np.ndarray
    edges: np.ndarray
    faces: np.ndarray
    component: np.ndarray
    knn: np.ndarray

    @property
    def n_points(self) -> int:
        """Number of welded points P."""
        return int(len(self.points))

    def edge_lengths(self) -> np.ndarray:
        """(E,) float64 length of every edge."""
        return np.linalg.norm(self.points[self.edges[:, 0]] - self.points[self.edges[:, 1]], axis=1)

    def adjacency(self, edges: np.ndarray | None = None) -> sp.csr_matrix:
        """(P, P) symmetric 0/1 sparse adjacency of the given edges (default: all)."""
        e = self.edges if edges is None else edges
        n = self.n_points
        data = np.ones(2 * len(e), np.int8)
        rows = np.concatenate([e[:, 0], e[:, 1]])
        cols = np.concatenate([e[:, 1], e[:, 0]])
        return sp.csr_matrix((data, (rows, cols)), shape=(n, n))


def check_mesh_arrays(vertices: np.ndarray, faces: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert to (V, 3) float64 and (T, 3) int64; raises MeshInputError on bad input."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshInputError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise MeshInputError("vertices contain NaN or infinite values")
    f = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces)
    if f.size == 0:
        f = np.zeros((0, 3), np.int64)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise MeshInputError(f"faces must be an integer array of shape (T, 3), got {f.shape} {f.dtype}")
    f = f.astype(np.int64)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise MeshInputError(f"face indices must lie in [0, {len(v)})")
    return v, f


def weld_points(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V,) welded id per vertex and (P, 3) welded positions; ids follow the first vertex of each point."""
    if len(v) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    diag = float(np.linalg.norm(np.ptp(v, axis=0))) or 1.0
    key = np.round((v - v.min(axis=0)) / (WELD_TOL * diag)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    weld = rank[inv]
    points = v[np.sort(first)]
    return weld, points


def _knn_edges(points: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """(E, 2) edges linking each of the points ``idx`` to its nearest others among ``idx``."""
    if len(idx) < 2:
        return np.zeros((0, 2), np.int64)
    k = min(KNN_ISOLATED, len(idx) - 1)
    _, nn = cKDTree(points[idx]).query(points[idx], k=k + 1)
    a = np.repeat(idx, k)
    b = idx[nn[:, 1:].reshape(-1)]
    return np.stack([a, b], axis=1)


def _unique_edges(e: np.ndarray) -> np.ndarray:
    e = np.sort(e, axis=1)
    e = e[e[:, 0] != e[:, 1]]
    return np.unique(e, axis=0) if len(e) else np.zeros((0, 2), np.int64)


def weld_graph(vertices: np.ndarray, faces: np.ndarray | None) -> WeldedGraph:
    """Weld by position and build the edge graph; unreferenced points are linked to their nearest ones."""
    v, f = check_mesh_arrays(vertices, faces)
    weld, points = weld_points(v)
    wf = weld[f] if len(f) else np.zeros((0, 3), np.int64)
    good = (wf[:, 0] != wf[:, 1]) & (wf[:, 1] != wf[:, 2]) & (wf[:, 0] != wf[:, 2])
    wf = wf[good]
    face_edges = _unique_edges(np.concatenate([wf[:, [0, 1]], wf[:, [1, 2]], wf[:, [2, 0]]]))
    touched = np.zeros(len(points), bool)
    touched[face_edges.reshape(-1)] = True
    extra = _unique_edges(_knn_edges(points, np.flatnonzero(~touched)))
    edges = np.concatenate([face_edges, extra]).astype(np.int64)
    knn = np.concatenate([np.zeros(len(face_edges), bool), np.ones(len(extra), bool)])
    adj = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(points),) * 2)
    _, comp = connected_components(adj, directed=False)
    first = np.full(comp.max() + 1 if len(comp) else 0, len(points), np.int64)
    np.minimum.at(first, comp, np.arange(len(points)))
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return WeldedGraph(weld, points, edges, wf, rank[comp].astype(np.int64), knn)
