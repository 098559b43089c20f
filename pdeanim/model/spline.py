"""The natural-spline time model (docs/format.md §3.5): an item's knots interpolated in time by the natural
cubic spline through all of them, so frames between knots follow the curvature of the motion instead of its
chords.

The spline is C2 (every knot weighs on every segment, through one tridiagonal solve shared by all items) and
is the small-constant limit of the paper's sum of two time terms in one segment (span{cosh m1 t, sinh m1 t,
cosh m2 t, sinh m2 t} tends to span{1, t, t^2, t^3}). Here: the knot tangents, the per-frame weights of the
knots, the least-squares knots of such tracks (one QR of the dense design), and the per-item choice between
the spline and the paper's time pair.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from ..errors import PdeanimError
from .segments import Segmentation

CUBIC_GAIN = 1.5
"""An item is a spline candidate unless the spline's held-out error (between every other frame) exceeds this
multiple of the straight line's: the test is conservative, as it predicts over twice the spacing the clip is
played at (elephant-gallop fitted from every 4th frame: lines win that test by up to 1.25x on most items, yet
the cubic predicts the frames left out 13% better than lines). Items that do not move keep the paper's
pair."""


def hermite_basis(tau: Any) -> tuple[Any, Any, Any, Any]:
    """The cubic Hermite functions (h00, h01, h10, h11) at local times tau (an array or a float): value at the
    start and end, and the start and end tangents' shares."""
    omt, tt = 1.0 - tau, tau * tau
    return (1.0 + 2.0 * tau) * omt * omt, tt * (3.0 - 2.0 * tau), tau * omt * omt, tt * (tau - 1.0)


def spline_frame_weights(segment_t: list[float], s: int, tau: float) -> tuple[float, ...]:
    """(w_T_s, w_P_s, w_P_s+1, w_T_s+1) of the natural-spline cubic in segment s at local time tau (§3.5):
    the Hermite functions, the tangents' scaled by the segment's length; pure Python floats."""
    delta = segment_t[s + 1] - segment_t[s]
    h00, h01, h10, h11 = hermite_basis(tau)
    return delta * h10, h00, h01, delta * h11


def predict_spline(z: np.ndarray, segm: Segmentation) -> np.ndarray:
    """Spline model tracks (K, F, W) at the frames from knots z (K, S + 1, W)."""
    return _on_frames(spline_design(segm.segment_t, segm.frame_segment(), segm.frame_tau()), z)


def prefer_spline(b: np.ndarray, t: np.ndarray, gain: float = CUBIC_GAIN) -> np.ndarray:
    """(K,) bool: the moving items whose tracks b (K, F, W) at normalised times t (F,) the natural spline
    predicts between every other frame no worse than ``gain`` times straight lines do (each parity's interior
    frames predicted from the other parity's frames)."""
    e_lin, e_cub = spline_evidence(b, t)
    return (e_cub < gain * e_lin) & (e_lin > 0)


def spline_evidence(b: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) squared errors of straight lines and of the natural spline predicting the tracks b (K, F, W) at
    every other frame from the frames between (both parities summed); zeros below 4 frames. Sums over windows
    of frames add up to a whole sequence's evidence but for the frames next to window bounds."""
    K = b.shape[0]
    e_lin, e_cub = np.zeros(K), np.zeros(K)
    for lin, cub in _parity_residuals(b, t):
        e_lin += np.einsum("kfw,kfw->k", lin, lin)
        e_cub += np.einsum("kfw,kfw->k", cub, cub)
    return e_lin, e_cub


def spline_residuals(b: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lin, cub), each (K, n, W): what straight lines and the natural spline miss when they predict the
    tracks b (K, F, W) at every other frame from the frames between (both parities; n = 0 below 4 frames).
    Linear in b, so a windowed fit gathers their Gram matrices before it knows the space bases."""
    pairs = list(_parity_residuals(b, t))
    if not pairs:
        empty = np.zeros((b.shape[0], 0, b.shape[2]))
        return empty, empty
    return np.concatenate([p[0] for p in pairs], axis=1), np.concatenate([p[1] for p in pairs], axis=1)


def _parity_residuals(b: np.ndarray, t: np.ndarray):  # noqa: ANN202
    """Per parity (none below 4 frames), the residuals (lin, cub) (K, n, W) of :func:`spline_residuals`."""
    F = b.shape[1]
    if F < 4:
        return
    t = np.asarray(t, np.float64)
    for parity in (0, 1):
        kept = np.arange(parity, F, 2)
        out = np.setdiff1d(np.arange(kept[0] + 1, kept[-1]), kept)
        seg = np.clip(np.searchsorted(t[kept], t[out], side="right") - 1, 0, len(kept) - 2)
        tau = (t[out] - t[kept][seg]) / (t[kept][seg + 1] - t[kept][seg])
        target = b[:, out]
        cub = _on_frames(spline_design(t[kept], seg, tau), b[:, kept]) - target
        lin = (b[:, kept[seg]] * (1.0 - tau)[:, None] + b[:, kept[seg + 1]] * tau[:, None]) - target
        yield lin, cub


def natural_tangents(P: np.ndarray, segment_t: np.ndarray) -> np.ndarray:
    """Knot tangents (S + 1, ...) float64 of the natural cubic spline through per-knot data P (S + 1, ...) at
    strictly increasing times segment_t (docs/format.md §3.5): the tridiagonal system solved by the Thomas
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


def clamped_tangents(P: np.ndarray, segment_t: np.ndarray, first: np.ndarray | None,
                     last: np.ndarray | None) -> np.ndarray:
    """Knot tangents (S + 1, ...) float64 of the cubic spline through P (S + 1, ...) at strictly increasing
    times segment_t with the given end tangents (``first``, ``last``: float64 like P[0]; None keeps that
    end's natural condition, docs/format.md §3.5.2): the natural spline's system with a known end's row
    replaced by T = value, solved by the Thomas algorithm. A window of a streamable clip (§3.10) given the
    whole clip's tangents at its ends gets the whole clip's tangents inside, to rounding; with both ends
    None this is :func:`natural_tangents`."""
    if first is None and last is None:
        return natural_tangents(P, segment_t)
    t = np.asarray(segment_t, np.float64)
    S = len(t) - 1
    P = np.asarray(P, np.float64)
    if S < 1 or not np.all(np.diff(t) > 0):
        raise PdeanimError("spline tangents need at least two strictly increasing knot times")
    dx = np.diff(t)
    d = np.diff(P, axis=0) / dx.reshape(-1, *([1] * (P.ndim - 1)))
    lower = np.r_[0.0, dx[1:], 1.0]  # coefficient of T_{j-1} in row j
    diag = np.r_[2.0, 2.0 * (dx[:-1] + dx[1:]), 2.0]
    upper = np.r_[1.0, dx[:-1], 0.0]  # coefficient of T_{j+1}
    out = np.empty_like(P)
    out[0] = 3.0 * d[0]
    for j in range(1, S):
        out[j] = 3.0 * (dx[j] * d[j - 1] + dx[j - 1] * d[j])
    out[S] = 3.0 * d[S - 1]
    if first is not None:  # row 0 becomes T_0 = first
        diag[0], upper[0], out[0] = 1.0, 0.0, first
    if last is not None:  # row S becomes T_S = last
        diag[S], lower[S], out[S] = 1.0, 0.0, last
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


def solve_spline_knots(b: np.ndarray, segm: Segmentation) -> np.ndarray:
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
