"""Structured tetrahedral meshes of a box (a bar of n x m x k cubes): exact, fast meshes for tests."""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .tetmesh import TetMesh, clean_tet_mesh

# cube corners numbered by bits: corner b sits at (b & 1, (b >> 1) & 1, (b >> 2) & 1)
SIX_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
"""Kuhn split along the 0-7 diagonal: conforming between neighbouring cubes without alternation."""
FIVE_TETS = np.array([[0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7], [1, 2, 4, 7]])
"""Corner tets plus a central one; mirrored (b ^ 1) on odd cubes so neighbouring faces share diagonals."""


def box_tet_mesh(size: tuple[float, float, float], cells: tuple[int, int, int], split: int = 6,
                 origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> TetMesh:
    """A box of ``size`` split into ``cells`` cubes (nx, ny, nz), each into 5 or 6 positive tets."""
    nx, ny, nz = (int(c) for c in cells)
    if min(nx, ny, nz) < 1 or split not in (5, 6):
        raise ParameterError(f"box needs cells >= 1 and split 5 or 6, got {cells}, {split}")
    axes = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, size, (nx, ny, nz), strict=True)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    points = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    bits = np.arange(8)
    corner = ((i[:, None] + (bits & 1)) * (ny + 1) + j[:, None] + ((bits >> 1) & 1)) * (nz + 1) \
        + k[:, None] + ((bits >> 2) & 1)
    if split == 6:
        tets = corner[:, SIX_TETS].reshape(-1, 4)
    else:
        odd = ((i + j + k) % 2 == 1)[:, None, None]
        tets = np.where(odd, corner[:, FIVE_TETS ^ 1], corner[:, FIVE_TETS]).reshape(-1, 4)
    return clean_tet_mesh(points, tets)
