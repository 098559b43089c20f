"""Smooth scalar fields on a welded mesh whose iso-lines become the extracted curves.

Fields are computed per connected component and scaled so that their surface gradient is about 1, so a band
of width h in field value is about h wide on the surface.

* ``axis``: coordinate along each component's principal axis (vectorised over components).
* ``fiedler``: the first non-constant eigenvector of the cotangent Laplacian (generalised with the lumped
  mass matrix), following the shape along the surface; one sparse LU per component.
* ``geodesic``: half the difference of the graph-geodesic distances from the two poles of the Fiedler vector,
  so bands keep their surface width near the poles as well.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import dijkstra

from .weld import WeldedGraph

FIELDS = ("axis", "fiedler", "geodesic")
MIN_SPECTRAL_POINTS = 24  # smaller components use the axis field
INVERSE_ITERATIONS = 10  # floors on spot/bob identical to 3 digits from 10 to 40 steps
COT_CAP = 1e3


def group_pca(x: np.ndarray, labels: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-group mean (G, 3) and principal axes (G, 3, 3) (columns by decreasing variance) of points (N,
    3)."""
    cnt = np.maximum(np.bincount(labels, minlength=n_groups), 1).astype(np.float64)
    mean = np.stack([np.bincount(labels, x[:, i], n_groups) for i in range(3)], axis=1) / cnt[:, None]
    d = x - mean[labels]
    cov = np.empty((n_groups, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.bincount(labels, d[:, i] * d[:, j], n_groups) / cnt
    _, vec = np.linalg.eigh(cov)
    vec = vec[:, :, ::-1]
    # deterministic sign: the largest entry of every axis is positive
    big = np.take_along_axis(vec, np.abs(vec).argmax(axis=1)[:, None, :], axis=1)
    vec = vec * np.where(big < 0, -1.0, 1.0)
    return mean, vec


def axis_field(g: WeldedGraph) -> np.ndarray:
    """(P,) float64 coordinate of every point along its component's principal axis."""
    n = int(g.component.max()) + 1 if g.n_points else 0
    mean, vec = group_pca(g.points, g.component, n)
    return np.einsum("pi,pi->p", g.points - mean[g.component], vec[g.component, :, 0])


def cotangent_laplacian(g: WeldedGraph) -> tuple[sp.csr_matrix, np.ndarray]:
    """(P, P) cotangent stiffness (weights clamped to [0, cap], plus a small uniform term) and (P,) lumped
    mass."""
    p, f = g.points, g.faces
    n = g.n_points
    rows, cols, vals = [], [], []
    area = np.zeros(n)
    if len(f):
        tri = p[f]
        a2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        for k in range(3):
            i, j = f[:, (k + 1) % 3], f[:, (k + 2) % 3]
            e1, e2 = p[i] - p[f[:, k]], p[j] - p[f[:, k]]
            cot = np.einsum("ij,ij->i", e1, e2) / np.maximum(a2, 1e-300)
            rows += [i, j]
            cols += [j, i]
            vals += [np.clip(0.5 * cot, 0.0, COT_CAP)] * 2
            np.add.at(area, f[:, k], a2 / 6.0)
    e = g.edges
    w = sp.csr_matrix(
        (
            np.concatenate(vals) if vals else np.zeros(0),
            (
                np.concatenate(rows) if rows else np.zeros(0, int),
                np.concatenate(cols) if cols else np.zeros(0, int),
            ),
        ),
        shape=(n, n),
    )
    uni = sp.csr_matrix(
        (np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)
    )
    mean_w = float(w.data.mean()) if w.nnz else 1.0
    w = w + 1e-2 * mean_w * uni
    lap = sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w
    area = np.where(area > 0, area, area[area > 0].mean() if np.any(area > 0) else 1.0)
    return lap.tocsr(), area


def _fiedler(lap: sp.csr_matrix, mass: np.ndarray, start: np.ndarray) -> np.ndarray | None:
    """Second generalised eigenvector of (lap, diag(mass)) by shifted inverse iteration (one LU); None on
    failure.

    The constant null vector is projected out every step; the accuracy needed for banding and directions is
    reached in ``INVERSE_ITERATIONS`` steps from a start near the answer (the principal-axis coordinate).
    """
    scale = float(lap.diagonal().mean() / mass.mean())
    try:
        lu = spla.splu((lap + 1e-3 * scale * sp.diags(mass)).tocsc())
    except RuntimeError:
        return None
    x = start.astype(np.float64)
    for _ in range(INVERSE_ITERATIONS):
        x = x - (x @ mass) / mass.sum()
        x = lu.solve(mass * x)
        norm = np.sqrt(x @ (mass * x))
        if not (np.isfinite(norm) and norm > 0):
            return None
        x /= norm
    return x if np.all(np.isfinite(x)) and np.ptp(x) > 0 else None


def _normalise(f: np.ndarray, g: WeldedGraph) -> np.ndarray:
    """Scale each component's field so the median over points of the steepest edge slope is 1."""
    e = g.edges
    slope = np.abs(f[e[:, 0]] - f[e[:, 1]]) / np.maximum(g.edge_lengths(), 1e-300)
    steep = np.zeros(g.n_points)
    np.maximum.at(steep, e[:, 0], slope)
    np.maximum.at(steep, e[:, 1], slope)
    pos = steep > 0
    comp = g.component[pos]
    order = np.lexsort((steep[pos], comp))
    n = int(g.component.max()) + 1 if g.n_points else 0
    cnt = np.bincount(comp, minlength=n)
    start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
    med = np.ones(n)
    has = cnt > 0
    med[has] = steep[pos][order][start[has] + cnt[has] // 2]
    return f / med[g.component]


def spectral_field(g: WeldedGraph, kind: str, seed: int = 0) -> np.ndarray:
    """(P,) float64 ``fiedler`` or ``geodesic`` field; small or face-less components use the axis field."""
    f = axis_field(g)
    sizes = np.bincount(g.component)
    big = np.flatnonzero(sizes >= MIN_SPECTRAL_POINTS)
    if len(big) == 0 or len(g.faces) == 0:
        return f
    lap, mass = cotangent_laplacian(g)
    lengths = g.edge_lengths()
    graph = sp.csr_matrix((np.r_[lengths, lengths], (np.r_[g.edges[:, 0], g.edges[:, 1]],
                                                     np.r_[g.edges[:, 1], g.edges[:, 0]])), shape=lap.shape)
    for c in big:
        idx = np.flatnonzero(g.component == c)
        noise = np.random.default_rng(seed + int(c)).standard_normal(len(idx))
        start = f[idx] + 1e-3 * (np.std(f[idx]) or 1.0) * noise
        x = _fiedler(lap[idx][:, idx], mass[idx], start)
        if x is None:
            continue
        if np.dot(x - x.mean(), f[idx]) < 0:
            x = -x
        if kind == "geodesic":
            d = dijkstra(graph[idx][:, idx], indices=[int(np.argmin(x)), int(np.argmax(x))])
            x = 0.5 * (d[0] - d[1])
        f[idx] = x
    return f


def scalar_field(g: WeldedGraph, kind: str, seed: int = 0) -> np.ndarray:
    """(P,) float64 field of the given kind with surface gradient about 1 on every component."""
    f = axis_field(g) if kind == "axis" else spectral_field(g, kind, seed)
    return _normalise(f, g)
