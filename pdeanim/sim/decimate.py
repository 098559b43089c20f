"""Reduce a large surface before tetrahedralization.

trimesh's quadric decimation with its backend fast-simplification (a dependency): it keeps a clean manifold
surface, which fTetWild tetrahedralizes several times faster than a clustered soup. The fallback, for builds
without it, snaps vertices to a uniform grid and keeps one vertex per cell: crude for rendering but enough for
a simulation cage, since fTetWild accepts the non-manifold soup clustering can leave and rebuilds a volume.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import numpy as np


def cluster_vertices(vertices: np.ndarray, faces: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Snap (V, 3) vertices to a grid of ``cell`` size; returns (V', 3) representatives and the (T', 3) faces.

    Each cell is represented by its input vertex nearest to the cell's mean: unlike the mean itself it lies on
    the surface, so convex parts do not shrink.
    """
    keys = np.floor((vertices - vertices.min(axis=0)) / cell).astype(np.int64)
    _, label = np.unique(keys, axis=0, return_inverse=True)
    label = label.reshape(-1)
    n = int(label.max()) + 1
    counts = np.bincount(label, minlength=n).astype(np.float64)
    means = (
        np.stack([np.bincount(label, vertices[:, d], minlength=n) for d in range(3)], axis=1)
        / counts[:, None]
    )
    dist = np.linalg.norm(vertices - means[label], axis=1)
    order = np.lexsort((np.arange(len(label)), dist, label))  # per cell: nearest first, ties by index
    first = order[np.flatnonzero(np.r_[True, np.diff(label[order]) != 0])]
    means = vertices[first]
    new_faces = label[faces]
    keep = (new_faces[:, 0] != new_faces[:, 1]) & (new_faces[:, 1] != new_faces[:, 2]) \
        & (new_faces[:, 2] != new_faces[:, 0])
    new_faces = new_faces[keep]
    _, first = np.unique(np.sort(new_faces, axis=1), axis=0, return_index=True)
    return means, new_faces[np.sort(first)]


def decimation_method() -> str:
    """Which reduction :func:`decimate` applies here, with the library version it depends on (part of the tet
    cache key: another method gives another surface and so other tets)."""
    try:
        return f"quadric fast-simplification {version('fast-simplification')}"
    except PackageNotFoundError:
        return "vertex-clustering"


def quadric_decimate(
    vertices: np.ndarray, faces: np.ndarray, max_faces: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """Quadric decimation via trimesh when fast-simplification is importable, else None."""
    try:
        import fast_simplification  # noqa: F401
        import trimesh
    except ImportError:
        return None
    reduced = trimesh.Trimesh(vertices, faces, process=False).simplify_quadric_decimation(
        face_count=max_faces
    )
    return np.asarray(reduced.vertices, np.float64), np.asarray(reduced.faces, np.int64)


def decimate(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Reduce to at most ``max_faces`` (T, 3) faces (unchanged if already small enough): quadric decimation
    when fast-simplification is installed, else vertex clustering on a grid coarsened until few enough
    remain."""
    if len(faces) <= max_faces:
        return vertices, faces
    quadric = quadric_decimate(vertices, faces, max_faces)
    if quadric is not None:
        return quadric
    extent = float(np.ptp(vertices, axis=0).max())
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1).sum()
    cell = max(np.sqrt(2.0 * area / max_faces), extent * 1e-4)  # ~ edge length giving max_faces triangles
    for _ in range(20):
        v, f = cluster_vertices(vertices, faces, cell)
        if len(f) <= max_faces:
            return v, f
        cell *= 1.25
    return v, f
