"""Time tangents: cubic knot tracks, Catmull-Rom (format version 4, docs/format.md §3.10) or natural spline
(version 5, §3.11).

An item with tangents interpolates its knots on linear segments with a cubic Hermite spline, so frames
between knots follow the curvature of the motion instead of its chords. Its knot tangents are the central
differences of the neighbouring knots (one-sided at the ends; C1, four knots per segment) or those of the
natural cubic spline through all knots (C2; every knot weighs on every segment, through one tridiagonal
solve shared by all items). The cubic is the small-constant limit of the
paper's sum of two time terms in one segment (span{cosh m1 t, sinh m1 t, cosh m2 t, sinh m2 t} tends to
span{1, t, t^2, t^3}). Here: the weights of the four knots of a segment, the least-squares knots of such
tracks (a banded system, solved by a QR sweep), and the per-item choice between cubic and linear tracks.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from ..errors import PdeanimError
from .segments import Segmentation

CATMULL_ROM, NATURAL = "catmull-rom", "natural"
TANGENT_RULES = (CATMULL_ROM, NATURAL)

CUBIC_GAIN = 1.5
"""An item gets tangents unless the cubic's held-out error (between every other frame) exceeds this multiple
of the straight line's: the test is conservative, as it predicts over twice the spacing the clip is played
at (elephant-gallop fitted from every 4th frame: lines win that test by up to 1.25x on most items, yet the
cubic predicts the frames left out 13% better than lines). Items that do not move keep the linear pair."""


def hermite_basis(tau: Any) -> tuple[Any, Any, Any, Any]:
    """The cubic Hermite functions (h00, h01, h10, h11) at local times tau (an array or a float): value at the
    start and end, and the start and end tangents' shares."""
    omt, tt = 1.0 - tau, tau * tau
    return (1.0 + 2.0 * tau) * omt * omt, tt * (3.0 - 2.0 * tau), tau * omt * omt, tt * (tau - 1.0)


def hermite_weights(segment_t: np.ndarray, seg: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knot indices (n, 4) and float64 weights (n, 4) of the cubic at local times tau (n,) in segments seg
    (n,): knots lo(s), s, s+1, hi(s+1) with lo(s) = max(s - 1, 0), hi(s+1) = min(s + 2, S)."""
    t = np.asarray(segment_t, np.float64)
    S = len(t) - 1
    seg = np.asarray(seg, np.int64)
    tau = np.asarray(tau, np.float64)
    lo, hi = np.maximum(seg - 1, 0), np.minimum(seg + 2, S)
    delta = t[seg + 1] - t[seg]
    span0, span1 = t[np.minimum(seg + 1, S)] - t[lo], t[hi] - t[seg]
    a = np.divide(delta, span0, out=np.zeros_like(delta), where=span0 > 0)
    b = np.divide(delta, span1, out=np.zeros_like(delta), where=span1 > 0)
    h00, h01, h10, h11 = hermite_basis(tau)
    idx = np.stack([lo, seg, seg + 1, hi], axis=-1)
    w = np.stack([-a * h10, h00 - b * h11, h01 + a * h10, b * h11], axis=-1)
    return idx, w


def cubic_weights(segment_t: list[float], s: int, tau: float) -> tuple[int, int, tuple[float, ...]]:
    """(lo, hi, (w_lo, w_s, w_s+1, w_hi)) of one segment s at local time tau, in pure Python (a frame's
    evaluation): the same float64 arithmetic as :func:`hermite_weights`."""
    S = len(segment_t) - 1
    lo, hi = max(s - 1, 0), min(s + 2, S)
    delta = segment_t[s + 1] - segment_t[s]
    span0, span1 = segment_t[min(s + 1, S)] - segment_t[lo], segment_t[hi] - segment_t[s]
    a = delta / span0 if span0 > 0 else 0.0
    b = delta / span1 if span1 > 0 else 0.0
    h00, h01, h10, h11 = hermite_basis(tau)  # plain floats in, plain floats out
    return lo, hi, (-a * h10, h00 - b * h11, h01 + a * h10, b * h11)


def spline_frame_weights(segment_t: list[float], s: int, tau: float) -> tuple[float, ...]:
    """(w_T_s, w_P_s, w_P_s+1, w_T_s+1) of the natural-spline cubic in segment s at local time tau (§3.11):
    the Hermite functions, the tangents' scaled by the segment's length; pure Python floats."""
    delta = segment_t[s + 1] - segment_t[s]
    h00, h01, h10, h11 = hermite_basis(tau)
    return delta * h10, h00, h01, delta * h11


def band_weights(segm: Segmentation) -> np.ndarray:
    """(F, 4) weights of every frame on the consecutive knots s-1, s, s+1, s+2 of its segment s (ends folded
    onto the knots they clamp to, so a weight on a knot outside 0..S is 0)."""
    seg = segm.frame_segment()
    idx, w = hermite_weights(segm.segment_t, seg, segm.frame_tau())
    out = np.zeros_like(w)
    for j in range(4):  # column j of the band is knot s - 1 + j; a clamped index lands on its real column
        np.add.at(out, (np.arange(len(seg)), idx[:, j] - seg + 1), w[:, j])
    return out


def solve_cubic_knots(b: np.ndarray, segm: Segmentation, rule: str = CATMULL_ROM) -> np.ndarray:
    """Least-squares knots z (K, S + 1, W) of tracks b (K, F, W) under the cubic model of ``rule``."""
    if rule == NATURAL:
        return _solve_spline_knots(b, segm)
    return _solve_catmull_rom_knots(b, segm)


def _solve_catmull_rom_knots(b: np.ndarray, segm: Segmentation) -> np.ndarray:
    """Least-squares Catmull-Rom knots z (K, S + 1, W) of tracks b (K, F, W), by a QR sweep.

    Every item shares the design (F rows, four consecutive knots each), so the sweep runs once with the
    K * W tracks as right-hand sides. Knots -1 and S + 1 are padding unknowns pinned to 0.
    """
    K, F, W = b.shape
    S = segm.n_segments
    A = band_weights(segm)  # (F, 4) on padded unknowns s .. s + 3 (padded index = knot + 1)
    rhs = np.moveaxis(b, 1, 0).reshape(F, K * W)
    seg = segm.frame_segment()
    n_cols = 4 + K * W
    rows = np.empty((S + 3, n_cols))  # finished equation of padded unknown i: row i on unknowns i .. i + 3
    carry = np.zeros((3, n_cols))  # pending rows on the next three unknowns (band columns 0..2)
    carry[0, 0] = 1.0  # knot -1 = 0
    starts = np.searchsorted(seg, np.arange(S + 1))
    for s in range(S):
        lo, hi = int(starts[s]), int(starts[s + 1])
        block = np.zeros((3 + hi - lo, n_cols))
        block[:3, :3], block[:3, 4:] = carry[:, :3], carry[:, 4:]
        block[3:, :4], block[3:, 4:] = A[lo:hi], rhs[lo:hi]
        R = np.linalg.qr(block, mode="r")
        R = np.vstack([R, np.zeros((4 - len(R), n_cols))]) if len(R) < 4 else R[:4]
        rows[s] = R[0]
        carry = np.zeros((3, n_cols))
        carry[:, :3], carry[:, 4:] = R[1:4, 1:4], R[1:4, 4:]
    tail = np.zeros((4, n_cols))  # the last three unknowns: knots S - 1, S and the padding knot S + 1 = 0
    tail[:3, :3], tail[:3, 4:] = carry[:, :3], carry[:, 4:]
    tail[3, 2] = 1.0
    R = np.linalg.qr(tail[:, [0, 1, 2, *range(4, n_cols)]], mode="r")
    x = np.zeros((S + 3, K * W))
    for i in (2, 1, 0):  # padded unknowns S, S + 1, S + 2
        acc = R[i, 3:] - sum(R[i, j] * x[S + j] for j in range(i + 1, 3))
        x[S + i] = _divide(acc, R[i, i], S + i - 1)
    for i in range(S - 1, -1, -1):
        acc = rows[i, 4:] - rows[i, 1] * x[i + 1] - rows[i, 2] * x[i + 2] - rows[i, 3] * x[i + 3]
        x[i] = _divide(acc, rows[i, 0], i - 1)
    return np.moveaxis(x[1:S + 2].reshape(S + 1, K, W), 1, 0)


def _divide(num: np.ndarray, pivot: float, knot: int) -> np.ndarray:
    """num / pivot in the back substitution; a zero pivot means no frame determines the knot."""
    if not abs(pivot) > 1e-300:
        raise PdeanimError(f"time fit: cubic knot {knot} is not determined by any frame (zero pivot)")
    return num / pivot


def predict_cubic(z: np.ndarray, segm: Segmentation, rule: str = CATMULL_ROM) -> np.ndarray:
    """Cubic model tracks (K, F, W) at the frames from knots z (K, S + 1, W)."""
    if rule == NATURAL:
        return _on_frames(spline_design(segm.segment_t, segm.frame_segment(), segm.frame_tau()), z)
    idx, w = hermite_weights(segm.segment_t, segm.frame_segment(), segm.frame_tau())
    out = np.take(z, idx[:, 0], axis=1) * w[None, :, 0, None]
    for j in range(1, 4):
        out += np.take(z, idx[:, j], axis=1) * w[None, :, j, None]
    return out


def prefer_tangents(b: np.ndarray, t: np.ndarray, rule: str = CATMULL_ROM) -> np.ndarray:
    """(K,) bool: the moving items whose tracks b (K, F, W) at normalised times t (F,) the cubic predicts
    between every other frame no worse than CUBIC_GAIN times straight lines do (each interior frame predicted
    from the frames two apart around it; for the natural spline, from the spline through the other parity's
    frames)."""
    K, F, _ = b.shape
    if F < 4:
        return np.zeros(K, bool)
    t = np.asarray(t, np.float64)
    if rule == NATURAL:
        return _prefer_spline(b, t)
    f = np.arange(1, F - 1)
    p0, p1 = f - 1, f + 1
    lo, hi = np.where(f - 3 >= 0, f - 3, p0), np.where(f + 3 <= F - 1, f + 3, p1)
    delta = t[p1] - t[p0]
    tau = np.divide(t[f] - t[p0], delta, out=np.zeros_like(delta), where=delta > 0)
    span0, span1 = t[p1] - t[lo], t[hi] - t[p0]
    a = np.divide(delta, span0, out=np.zeros_like(delta), where=span0 > 0)
    c = np.divide(delta, span1, out=np.zeros_like(delta), where=span1 > 0)
    h00, h01, h10, h11 = hermite_basis(tau)
    B0, B1, target = b[:, p0], b[:, p1], b[:, f]
    lin = B0 * (1.0 - tau)[:, None] + B1 * tau[:, None] - target
    cub = (B0 * h00[:, None] + B1 * h01[:, None] + (B1 - b[:, lo]) * (a * h10)[:, None]
           + (b[:, hi] - B0) * (c * h11)[:, None] - target)
    e_lin = np.einsum("kfw,kfw->k", lin, lin)
    e_cub = np.einsum("kfw,kfw->k", cub, cub)
    return (e_cub < CUBIC_GAIN * e_lin) & (e_lin > 0)


def natural_tangents(P: np.ndarray, segment_t: np.ndarray) -> np.ndarray:
    """Knot tangents (S + 1, ...) float64 of the natural cubic spline through per-knot data P (S + 1, ...) at
    strictly increasing times segment_t (docs/format.md §3.11): the tridiagonal system solved by the Thomas
    algorithm (strictly diagonally dominant), one sweep over the knots for every column at once."""
    t = np.asarray(segment_t, np.float64)
    S = len(t) - 1
    P = np.asarray(P, np.float64)
    dx = np.diff(t).reshape(-1, *([1] * (P.ndim - 1)))
    if S < 1 or not np.all(dx > 0):
        raise PdeanimError("natural-spline tangents need at least two strictly increasing knot times")
    d = np.diff(P, axis=0) / dx
    dx = np.diff(t)
    lower = np.r_[0.0, dx[1:], 1.0]  # coefficient of T_{j-1} in row j
    diag = np.r_[2.0, 2.0 * (dx[:-1] + dx[1:]), 2.0]
    upper = np.r_[1.0, dx[:-1], 0.0]  # coefficient of T_{j+1}
    out = np.empty_like(P)
    out[0] = 3.0 * d[0]
    for j in range(1, S):
        out[j] = 3.0 * (dx[j] * d[j - 1] + dx[j - 1] * d[j])
    out[S] = 3.0 * d[S - 1]
    c = np.empty(S + 1)
    c[0] = upper[0] / diag[0]
    out[0] /= diag[0]
    for j in range(1, S + 1):  # forward elimination
        piv = diag[j] - lower[j] * c[j - 1]
        c[j] = upper[j] / piv
        out[j] -= lower[j] * out[j - 1]
        out[j] /= piv
    for j in range(S - 1, -1, -1):  # back substitution
        out[j] -= c[j] * out[j + 1]
    return out


def spline_design(segment_t: np.ndarray, seg: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(n, S + 1) float64 weights of every knot on the natural-spline cubic at local times tau (n,) in
    segments seg (n,): value = h00 P_s + h01 P_s+1 + delta (h10 T_s + h11 T_s+1), with T = M P."""
    t = np.asarray(segment_t, np.float64)
    S = len(t) - 1
    M = natural_tangents(np.eye(S + 1), t)  # T_j = sum_i M[j, i] P_i
    seg = np.asarray(seg, np.int64)
    h00, h01, h10, h11 = hermite_basis(np.asarray(tau, np.float64))
    delta = t[seg + 1] - t[seg]
    W = (delta * h10)[:, None] * M[seg] + (delta * h11)[:, None] * M[seg + 1]
    rows = np.arange(len(seg))
    W[rows, seg] += h00
    W[rows, seg + 1] += h01
    return W


def spline_weight_bound(segment_t: np.ndarray, t: np.ndarray) -> float:
    """Largest sum of absolute knot weights of the natural-spline cubic at normalised times t (n,): how far
    a rounding of every knot by at most e can move a value (at most e times this)."""
    seg_t = np.asarray(segment_t, np.float64)
    t = np.clip(np.asarray(t, np.float64), seg_t[0], seg_t[-1])
    seg = np.clip(np.searchsorted(seg_t, t, side="right") - 1, 0, len(seg_t) - 2)
    tau = (t - seg_t[seg]) / (seg_t[seg + 1] - seg_t[seg])
    return float(np.abs(spline_design(seg_t, seg, tau)).sum(axis=1).max(initial=1.0))


def _on_frames(W: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Tracks (K, n, Wd) = W (n, S + 1) applied to knots z (K, S + 1, Wd), as one matrix product."""
    K, S1, Wd = z.shape
    flat = np.moveaxis(z, 1, 0).reshape(S1, K * Wd)
    return np.moveaxis((W @ flat).reshape(len(W), K, Wd), 1, 0)


def _solve_spline_knots(b: np.ndarray, segm: Segmentation) -> np.ndarray:
    """Least-squares natural-spline knots z (K, S + 1, W) of tracks b (K, F, W): one QR of the dense design
    (F, S + 1) for every item (full column rank: every knot is a frame, where its row is a unit vector)."""
    K, F, Wd = b.shape
    if segm.n_segments == F - 1:  # a knot at every frame: the spline interpolates them, the design is I
        return np.array(b, dtype=np.float64)
    W = spline_design(segm.segment_t, segm.frame_segment(), segm.frame_tau())
    Q, R = np.linalg.qr(W)
    if not np.all(np.abs(np.diag(R)) > 1e-12):
        raise PdeanimError("time fit: a natural-spline knot is not determined by any frame")
    rhs = Q.T @ np.moveaxis(b, 1, 0).reshape(F, K * Wd)
    z = solve_triangular(R, rhs)
    return np.moveaxis(z.reshape(len(R), K, Wd), 1, 0)


def _prefer_spline(b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:func:`prefer_tangents` for the natural spline: each parity's interior frames predicted from the
    other parity's frames, by the spline through them and by straight lines."""
    K, F, _ = b.shape
    e_lin, e_cub = np.zeros(K), np.zeros(K)
    for parity in (0, 1):
        kept = np.arange(parity, F, 2)
        out = np.setdiff1d(np.arange(kept[0] + 1, kept[-1]), kept)
        seg = np.clip(np.searchsorted(t[kept], t[out], side="right") - 1, 0, len(kept) - 2)
        tau = (t[out] - t[kept][seg]) / (t[kept][seg + 1] - t[kept][seg])
        target = b[:, out]
        cub = _on_frames(spline_design(t[kept], seg, tau), b[:, kept]) - target
        lin = (b[:, kept[seg]] * (1.0 - tau)[:, None] + b[:, kept[seg + 1]] * tau[:, None]) - target
        e_lin += np.einsum("kfw,kfw->k", lin, lin)
        e_cub += np.einsum("kfw,kfw->k", cub, cub)
    return (e_cub < CUBIC_GAIN * e_lin) & (e_lin > 0)
