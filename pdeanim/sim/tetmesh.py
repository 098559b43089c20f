"""A tetrahedral mesh (points + tets) with the checks every tetrahedralizer's output goes through."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TetrahedralizationError

DEGENERATE_REL_VOLUME = 1e-9
"""A tet whose volume is below this fraction of the mean tet volume is dropped as degenerate."""


@dataclass(frozen=True)
class TetMesh:
    """A tetrahedral mesh.

    points : (N, 3) float64 rest positions
    tets : (M, 4) int64 point indices, positively oriented (det[p1-p0, p2-p0, p3-p0] > 0)
    """

    points: np.ndarray
    tets: np.ndarray

    @property
    def n_points(self) -> int:
        return int(len(self.points))

    @property
    def n_tets(self) -> int:
        return int(len(self.tets))

    def volumes(self) -> np.ndarray:
        """(M,) float64 signed volumes (all positive for a cleaned mesh)."""
        return tet_volumes(self.points, self.tets)

    def surface_faces(self) -> np.ndarray:
        """(S, 3) int64 boundary triangles (faces used by exactly one tet), outward oriented."""
        local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
        faces = self.tets[:, local].reshape(-1, 3)
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return faces[counts[inverse.reshape(-1)] == 1]


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(M,) signed volumes of tets (M, 4) over points (N, 3)."""
    p = points[tets]
    d = p[:, 1:] - p[:, :1]
    return np.einsum("ij,ij->i", np.cross(d[:, 0], d[:, 1]), d[:, 2]) / 6.0


def clean_tet_mesh(points: np.ndarray, tets: np.ndarray) -> TetMesh:
    """Flip negatively oriented tets, drop degenerate ones and unused points; TetrahedralizationError if
    empty."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tets = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    if len(tets) == 0 or len(points) < 4:
        raise TetrahedralizationError("tetrahedralization produced no tetrahedra")
    if not np.all(np.isfinite(points)) or tets.min() < 0 or tets.max() >= len(points):
        raise TetrahedralizationError("tetrahedralization produced invalid points or indices")
    vol = tet_volumes(points, tets)
    flip = vol < 0
    tets = tets.copy()
    tets[flip, 1], tets[flip, 2] = tets[flip, 2], tets[flip, 1].copy()
    vol = np.abs(vol)
    keep = vol > DEGENERATE_REL_VOLUME * max(float(vol.mean()), np.finfo(float).tiny)
    tets = tets[keep]
    if len(tets) == 0:
        raise TetrahedralizationError("every tetrahedron is degenerate")
    used, remap = np.unique(tets, return_inverse=True)
    return TetMesh(points[used], remap.reshape(-1, 4).astype(np.int64))
