"""Embed surface vertices in a tet mesh with barycentric coordinates so they follow the simulation.

A vertex inside the tet mesh gets the tet containing it; one outside (fTetWild's surface lies within epsilon
of the input, not on it) gets, among its nearest tets, the one needing the least extrapolation, with its
unclamped barycentric coordinates: the vertex then follows that tet's affine motion and is reproduced exactly
at rest (clamping would snap it onto the tet).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .tetmesh import TetMesh

CANDIDATES = 16
"""Nearest tet centroids tested per vertex."""
INSIDE_TOL = -1e-9


@dataclass(frozen=True)
class Embedding:
    """tet : (V,) int64 tet of each vertex; bary : (V, 4) float64 barycentric coordinates; corners : (V,
    4)."""

    tet: np.ndarray
    bary: np.ndarray
    corners: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(V, 3) vertex positions for tet point positions (N, 3)."""
        return np.einsum("vk,vkd->vd", self.bary, points[self.corners])


def barycentric(points: np.ndarray, tets: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(..., 4) barycentric coordinates of query points q (..., 3) in tets (..., 4) over points (N, 3)."""
    p = points[tets]
    d = (p[..., 1:, :] - p[..., :1, :]).swapaxes(-1, -2)  # (..., 3, 3) columns p_i - p_0
    rhs = (q - p[..., 0, :])[..., None]
    b = np.linalg.solve(d, rhs)[..., 0]
    return np.concatenate([1.0 - b.sum(axis=-1, keepdims=True), b], axis=-1)


def embed_vertices(tets: TetMesh, vertices: np.ndarray, chunk: int = 65536) -> Embedding:
    """Containing (or least-extrapolating nearby) tet and barycentric coordinates of (V, 3) vertices."""
    tree = cKDTree(tets.points[tets.tets].mean(axis=1))
    parts = [embed_chunk(tets, tree, vertices[i:i + chunk]) for i in range(0, len(vertices), chunk)]
    tet = np.concatenate([p[0] for p in parts])
    bary = np.concatenate([p[1] for p in parts])
    return Embedding(tet, bary, tets.tets[tet])


def embed_chunk(tets: TetMesh, tree: cKDTree, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V,) tets and (V, 4) barycentric coordinates for one chunk of vertices (bounded memory)."""
    k = min(CANDIDATES, tets.n_tets)
    _, cand = tree.query(vertices, k=k)
    cand = np.asarray(cand).reshape(len(vertices), k)
    bary = barycentric(tets.points, tets.tets[cand], vertices[:, None, :])  # (V, k, 4)
    score = bary.min(axis=-1)
    inside = score >= INSIDE_TOL
    # first containing candidate (nearest centroid) if any, else the least extrapolating one
    best = np.where(inside.any(axis=1), np.argmax(inside, axis=1), np.argmax(score, axis=1))
    rows = np.arange(len(vertices))
    return cand[rows, best].astype(np.int64), bary[rows, best]
