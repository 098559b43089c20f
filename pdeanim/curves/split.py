"""Halving curves: the split step shared by error-bounded curves (:mod:`pdeanim.curves.bounded`) and the fit
(:mod:`pdeanim.fit.spacestage`), which splits the curves whose spatial floor is too large.

Splits never separate the copies of a welded (seam) vertex: a curve is cut between distinct points only.
"""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet


def distinct_rank(rest: np.ndarray, curves: CurveSet) -> tuple[np.ndarray, np.ndarray]:
    """(V,) index of each position in the order among its curve's distinct points, (C,) distinct count."""
    p = rest[curves.order]
    cid = np.repeat(np.arange(curves.n_curves), curves.lengths)
    new = np.r_[True, (cid[1:] != cid[:-1]) | np.any(p[1:] != p[:-1], axis=1)]
    rank = np.cumsum(new) - 1
    rank -= np.repeat(rank[curves.offsets[:-1]], curves.lengths)
    return rank, np.bincount(cid, new, curves.n_curves).astype(np.int64)


def split_curves(rest: np.ndarray, curves: CurveSet, bad: np.ndarray) -> CurveSet:
    """Split every curve flagged in bad (C,) with 2+ distinct points in two halves of distinct points."""
    rank, distinct = distinct_rank(rest, curves)
    cid = np.repeat(np.arange(curves.n_curves), curves.lengths)
    half = (distinct + 1) // 2
    cut = bad[cid] & (distinct[cid] >= 2) & (rank == half[cid]) & np.r_[True, rank[1:] != rank[:-1]]
    offsets = np.union1d(curves.offsets, np.flatnonzero(cut))
    return CurveSet(curves.order, offsets.astype(np.int32))
