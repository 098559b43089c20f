"""Welding an animation's duplicate vertices, as gltfpack does but lossless: vertices whose written data are
byte-for-byte equal (grid positions in every frame, normals as written, UVs and every other kept attribute)
become one, so a flat-shaded, unwelded low-poly mesh (every triangle corner its own vertex) shrinks to its
distinct vertices while vertices that meet at rest but move apart stay apart (gltfpack compares the rest
attributes only). Also: which meshes are flat-shaded (their vertex normals are their faces' normals, so a
glTF without normals, which viewers shade flat, shows them the same)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER
from .layout import accessor_rows, add_accessor, add_view, cache_order, minmax_of

VERTEX_MAP = "_PDEANIM_VERTEX"  # per written vertex: the clip vertex it shows (welded ones share motion)
FLAT_ANGLE = 1e-3  # radians: a vertex is flat when its incident faces' normals agree this closely
SMOOTH_ANGLE = np.radians(60.0)  # split vertices whose one-sided normals are this close: a seam, not an edge


@dataclass
class Welded:
    """``keep`` (m,): the source vertex each output vertex takes its data from (ascending, the first of its
    group); ``faces`` (T', 3) over the output vertices (triangles that welding made degenerate dropped)."""

    keep: np.ndarray
    faces: np.ndarray

    def identity(self, n_vertices: int) -> bool:
        """True when no vertex was merged or dropped."""
        return len(self.keep) == n_vertices


def row_bytes(*columns: np.ndarray) -> np.ndarray:
    """Per-vertex bytes (n, B) uint8 of arrays shaped (n, ...) side by side (the weld key)."""
    parts = [np.ascontiguousarray(c).reshape(len(c), -1).view(np.uint8) for c in columns]
    return np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]


def _labels(rows: np.ndarray) -> np.ndarray:
    """(n,) int64 label per row, equal for equal rows."""
    n, width = rows.shape
    if width == 0:
        return np.zeros(n, np.int64)
    void = np.ascontiguousarray(rows).view(np.dtype((np.void, width))).reshape(-1)
    return np.unique(void, return_inverse=True)[1].reshape(-1).astype(np.int64)


def weld_labels(rest: np.ndarray, motion: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(n,) group label per vertex: equal ``rest`` rows (n, B) and equal ``motion(idx)`` rows (len(idx), B')
    (the frames after the first, asked for only where the rest rows repeat, which keeps the per-frame
    comparison off meshes without duplicates)."""
    labels = _labels(rest)
    repeated = np.flatnonzero(np.bincount(labels)[labels] > 1)
    out = np.arange(len(labels), dtype=np.int64)
    if len(repeated):
        sub = _labels(row_bytes(labels[repeated], motion(repeated)))
        out[repeated] = len(labels) + sub
    return out


def smooth_groups(frames: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """(V,) normal groups of a mesh without source normals (frames (K, V, 3)): vertices at the same position
    in every frame share one smooth normal when their one-sided normals at rest (each from its own faces)
    are within :data:`SMOOTH_ANGLE` of each other, as at a UV seam or wherever an export split a smooth
    surface; across a hard edge (one-sided normals far apart) each side keeps its own. None when no vertex
    repeats."""
    from .normals import vertex_normals

    labels = weld_labels(row_bytes(frames[0]), lambda idx: row_bytes(frames[1:, idx].transpose(1, 0, 2)))
    group = np.unique(labels, return_inverse=True)[1].reshape(-1)
    if group.max() + 1 == len(group):
        return None
    one_sided = vertex_normals(frames[0], faces).astype(np.float64)
    sub = np.zeros(len(group), np.int64)
    left = np.flatnonzero(np.bincount(group)[group] > 1)
    rounds = 0
    while len(left):  # each round, every group's first unassigned member takes those close to it
        g = group[left]
        pivot = np.zeros(group.max() + 1, np.int64)
        pivot[g[::-1]] = left[::-1]
        close = np.einsum("ij,ij->i", one_sided[left], one_sided[pivot[g]]) >= np.cos(SMOOTH_ANGLE)
        sub[left[close]] = rounds
        left, rounds = left[~close], rounds + 1
    return np.unique(np.stack([group, sub], 1), axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)


def weld(labels: np.ndarray, faces: np.ndarray) -> Welded:
    """One output vertex per label, in order of first appearance (a mesh without duplicates keeps its vertex
    order), and the faces over them without the triangles that collapsed."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    new = rank[inverse.reshape(-1)]
    f = new[np.asarray(faces, np.int64).reshape(-1, 3)]
    solid = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    if solid.any():
        f = f[solid]
    return Welded(first[order].astype(np.int64), f)


def fetch_order(welded: Welded) -> Welded:
    """The vertices renumbered in the order the (cache-ordered) triangles first use them (meshoptimizer's
    vertex fetch order, what gltfpack writes): neighbouring vertices sit together, so the delta coding of
    EXT_meshopt_compression finds smaller steps. Vertices no triangle uses are dropped."""
    import meshoptimizer

    idx = np.ascontiguousarray(welded.faces.reshape(-1), np.uint32)
    remap = np.zeros(len(welded.keep), np.uint32)
    used = meshoptimizer.optimize_vertex_fetch_remap(remap, idx, len(idx), len(welded.keep))
    remap = remap.astype(np.int64)
    keep = np.empty(used, np.int64)
    live = remap < used  # unused vertices map to ~0u
    keep[remap[live]] = welded.keep[live]
    return Welded(keep, remap[welded.faces])


def flat_shaded(positions: np.ndarray, faces: np.ndarray) -> bool:
    """True when every vertex's incident (non-degenerate) faces are coplanar at ``positions`` (V, 3), i.e. its
    area-weighted normal is its faces' normal: flat normals (what a viewer computes for a glTF without
    NORMAL) look the same as vertex normals. A triangle soup is flat; a smooth mesh is not."""
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    if not len(f):
        return False
    p = np.asarray(positions, np.float64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    length = np.linalg.norm(fn, axis=1)
    ok = length > 1e-12 * max(float(np.ptp(p, axis=0).max()), 1e-300) ** 2
    if not ok.any():
        return False
    unit = fn[ok] / length[ok, None]
    corners = f[ok].reshape(-1)
    acc = np.zeros((len(p), 3))
    for k in range(3):
        acc[:, k] = np.bincount(corners, weights=np.repeat(fn[ok, k], 3), minlength=len(p))
    vn = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-300)
    cos = np.einsum("ij,ij->i", np.repeat(unit, 3, axis=0), vn[corners])
    return bool(cos.min() >= np.cos(FLAT_ANGLE))


def weld_primitive(doc: dict, views: list[bytes], prim: dict, pos: np.ndarray, normals: np.ndarray | None,
                   faces: np.ndarray, first_vertex: int) -> np.ndarray | None:
    """Weld one triangle primitive of a template whose vertices are clip vertices ``first_vertex`` on. Keys:
    its positions (K, n, 3) as written, ``normals`` (K', n, 3) as written (K' = 1 without normal targets)
    and its kept attributes (UVs...). Rewrites the primitive's indices (cache then fetch order) and
    attributes over the welded vertices and adds the :data:`VERTEX_MAP` attribute; returns ``keep`` (m,), the
    primitive's own vertex each written vertex takes its positions and normals from, or None when the
    primitive stays as it was (attributes the weld cannot follow). A primitive where nothing welds is
    reordered all the same, as gltfpack does: meshopt's codec codes each vertex against the one before, and a
    mesh in scan or capture order (samba) compresses to 0.62x in fetch order."""
    n = pos.shape[1]
    try:
        attrs = {name: accessor_rows(doc, views, acc) for name, acc in prim["attributes"].items()}
    except (ValueError, KeyError, IndexError, TypeError):  # an attribute past its view: written as it was
        return None
    if not len(faces) or any(len(v) != n for v in attrs.values()):
        return None

    def motion(idx: np.ndarray) -> np.ndarray:
        cols = [pos[1:, idx].transpose(1, 0, 2)]
        if normals is not None and len(normals) > 1:
            cols.append(normals[1:, idx].transpose(1, 0, 2))
        return row_bytes(*cols)

    rest = [pos[0], *([] if normals is None else [normals[0]]), *attrs.values()]
    welded = weld(weld_labels(row_bytes(*rest), motion), faces)
    welded.faces = cache_order(welded.faces, len(welded.keep))
    welded = fetch_order(welded)
    keep = welded.keep
    dtype = np.uint16 if len(keep) <= 65535 else np.uint32
    prim["indices"] = add_accessor(doc, views, welded.faces.reshape(-1).astype(dtype), "SCALAR",
                                   ELEMENT_ARRAY_BUFFER)
    prim["mode"] = 4
    for name, values in attrs.items():
        src = doc["accessors"][prim["attributes"][name]]
        prim["attributes"][name] = _vertex_attribute(doc, views, values[keep], src["type"],
                                                     bool(src.get("normalized")), "min" in src)
    prim["attributes"][VERTEX_MAP] = _vertex_map(doc, views, first_vertex + keep)
    return keep


def _vertex_attribute(doc: dict, views: list[bytes], values: np.ndarray, acc_type: str, normalized: bool,
                      minmax: bool) -> int:
    """An attribute accessor over (n, k) values in its own view, each element padded to the 4-byte stride
    glTF asks of vertex attributes (a VEC3 of bytes takes 4)."""
    elem = values.dtype.itemsize * values.shape[1]
    stride = -(-elem // 4) * 4
    rows = np.zeros((len(values), stride), np.uint8)
    little = np.ascontiguousarray(values, values.dtype.newbyteorder("<"))
    rows[:, :elem] = little.view(np.uint8).reshape(-1, elem)
    view = add_view(doc, views, rows.tobytes(), ARRAY_BUFFER, stride if stride != elem else None)
    acc = add_accessor(doc, views, values, acc_type, normalized=normalized, view=view)
    if minmax:
        doc["accessors"][acc].update(minmax_of(values.reshape(len(values), -1)))
    return acc


def map_all_or_none(doc: dict, views: list[bytes], prims: list[tuple[dict, int]]) -> None:
    """When some primitive has a :data:`VERTEX_MAP`, give one to every other (``(primitive, its first clip
    vertex)``, in clip order), so a player maps every mesh through it or, in a GLB without welds, none."""
    if not any(VERTEX_MAP in prim["attributes"] for prim, _ in prims):
        return
    for prim, first in prims:
        if VERTEX_MAP not in prim["attributes"]:
            count = int(doc["accessors"][prim["attributes"]["POSITION"]]["count"])
            prim["attributes"][VERTEX_MAP] = _vertex_map(doc, views, first + np.arange(count))


def _vertex_map(doc: dict, views: list[bytes], clip_vertex: np.ndarray) -> int:
    """The :data:`VERTEX_MAP` accessor: UNSIGNED_SHORT (padded to the 4-byte vertex stride glTF asks for)
    while the clip vertex indices fit, else FLOAT (exact below 2**24; UNSIGNED_INT is for indices only)."""
    dtype = np.uint16 if not len(clip_vertex) or clip_vertex.max() <= 65535 else np.float32
    return _vertex_attribute(doc, views, clip_vertex.astype(dtype)[:, None], "SCALAR", False, False)
