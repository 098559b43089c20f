"""A simple deterministic curve layout, used only when :mod:`pdeanim.curves.extract` is not available.

Vertices are cut into bands along the first principal axis of the rest positions; inside a band they are
ordered by angle around that axis, and a band's chain is cut where consecutive points jump far apart or
the run reaches ``max_points``. Every vertex lies on exactly one curve; no faces are needed.
"""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet


def simple_curves(vertices: np.ndarray, max_points: int = 24) -> CurveSet:
    """CurveSet over all vertices (V, 3) float: principal-axis bands ordered by angle, cut into runs."""
    p = np.asarray(vertices, dtype=np.float64)
    V = len(p)
    if V == 0:
        return CurveSet(np.zeros(0, np.int32), np.zeros(1, np.int32))
    c = p - p.mean(axis=0)
    _, _, Vt = np.linalg.svd(c, full_matrices=False) if V > 1 else (None, None, np.eye(3))
    axes = np.vstack([Vt, np.eye(3)])[:3]
    q = c @ axes.T
    n_bands = max(1, int(round(np.sqrt(V) / 2)))
    span = q[:, 0].max() - q[:, 0].min()
    width = span / n_bands if span > 0 else 1.0
    band = np.minimum(((q[:, 0] - q[:, 0].min()) / width).astype(np.int64), n_bands - 1)
    angle = np.round(np.arctan2(q[:, 2], q[:, 1]), 9)
    order = np.lexsort((np.arange(V), angle, band))
    gap = np.linalg.norm(np.diff(p[order], axis=0), axis=1)
    cut = (np.diff(band[order]) != 0) | (gap > 3.0 * max(width, 1e-12))
    starts = np.flatnonzero(np.concatenate([[True], cut]))
    lengths = np.diff(np.concatenate([starts, [V]]))
    pieces = np.ceil(lengths / max_points).astype(np.int64)
    sub = [np.round(np.linspace(s, s + n, k + 1)).astype(np.int64)[:-1]
           for s, n, k in zip(starts, lengths, pieces, strict=True)]
    offsets = np.unique(np.concatenate(sub + [np.array([V])]))
    return CurveSet(order.astype(np.int32), offsets.astype(np.int32))
