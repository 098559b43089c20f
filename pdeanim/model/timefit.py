"""The time half of the variable projection: C0 knot tracks with a time constant per segment (the paper's
time model), and natural-spline tracks (:mod:`pdeanim.model.spline`) for the items where they fit as well.

Every item (curve x coordinate) has a 4-vector track z(t) (its frames projected on the orthonormal space
basis). On segment s the model is z(tau) = z_s phi0(tau; mu_s) + z_{s+1} phi1(tau; mu_s), so adjacent
segments share a knot and the track is C0 by construction; for fixed mu the knots are one linear least
squares problem over all frames (banded design, solved by QR). mu (signed: > 0 exp, < 0 trig, 0 linear)
is chosen per item and segment: a coarse grid scored by the leave-one-out error of free per-segment fits
(so a constant is kept only where it predicts frames it did not see better than the linear pair; in-between
frames are then not pulled toward the rest pose by a sinh pair fitted to a few frames), then a
golden-section refinement with the knots fixed that must beat the current constant by a margin (a linear
pair stays exactly linear unless bending it clearly pays), vectorised over all items, then a final knot
solve. ``loop=True`` makes the knots
periodic (the last knot is the first) and restricts trig constants to multiples of 2 pi over the clip.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PdeanimError
from .families import MU_TRIG_MAX, time_pair
from .segments import Segmentation
from .spline import predict_spline, solve_spline_knots

MU_GRID = np.array([0.0, -MU_TRIG_MAX, -2.0, -1.0, -0.4, 0.4, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0])
"""Coarse grid of signed time constants per segment (0 first: ties keep the linear pair)."""
_CHUNK = 4_000_000
MU_CHOICE = "loo"
"""How the grid constant is scored: "loo" (leave-one-out error of the free per-segment fit, the default) or
"fit" (residual of the fit itself: smaller training error, worse in-between frames)."""
REFINE_GAIN = 0.0
"""Relative drop of a segment's error the golden refinement must bring to replace the current constant."""
MU_CAP_PER_INTERVAL = 1.0
"""|mu| of a segment is at most this times its number of frame intervals: the time pair then changes by a
bounded factor between two frames, so frames between the fitted ones follow the neighbouring frames instead of
an exponential boundary layer fitted to a few samples (measured: elephant-gallop fitted from every 4th frame
went from 1.33x worse than linear interpolation at the left-out frames, max 0.30 of the diagonal, to
equal)."""


def segment_pair(segm: Segmentation, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(phi0, phi1), each (K, F) float64: the signed time pair of every item at every frame, for constants
    mu (K, S) per segment; equals :func:`time_pair` at (frame_tau, mu[:, frame_segment]) bit for bit on the
    linear and exp rows and to ~1e-15 on trig rows (their sines come from :func:`sin_table`).

    Faster than the elementwise form: the linear pair is the default, and per segment only the rows with an
    exp or a trig constant are evaluated (same formulas, denominators computed once per row and segment).
    """
    seg, tau = segm.frame_segment(), segm.frame_tau()
    omt = 1.0 - tau
    K = len(mu)
    phi1 = np.empty((K, len(tau)))
    phi0 = np.empty((K, len(tau)))
    phi1[:] = tau
    phi0[:] = omt
    exp_rows, trig_rows = mu >= 1e-12, mu < 0
    mt = np.clip(-mu, 1e-150, MU_TRIG_MAX)
    for s in range(segm.n_segments):
        lo, hi = np.searchsorted(seg, s, "left"), np.searchsorted(seg, s, "right")
        if hi == lo:
            continue
        ts, os_ = tau[lo:hi], omt[lo:hi]
        rows = np.flatnonzero(exp_rows[:, s])
        if len(rows):
            m = mu[rows, s, None]
            n2 = -2.0 * m
            den = np.expm1(n2)
            phi1[rows, lo:hi] = np.exp(m * (ts - 1.0)) * np.expm1(n2 * ts) / den
            phi0[rows, lo:hi] = np.exp(m * (os_ - 1.0)) * np.expm1(n2 * os_) / den
        rows = np.flatnonzero(trig_rows[:, s])
        if len(rows):
            m = mt[rows, s]
            both = sin_table(m, np.concatenate([ts, os_]))
            both *= (1.0 / np.sin(m))[:, None]
            phi1[rows, lo:hi], phi0[rows, lo:hi] = both[:, :hi - lo], both[:, hi - lo:]
    return phi0, phi1


_SIN_TERMS = 15
SIN_COEF = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(_SIN_TERMS)])
"""Taylor coefficients of sin at the odd powers 1, 3, ..., 29 (to ~1e-15 for arguments up to pi)."""
_GEMM_SINGLE = 150_000
"""Largest rows x terms x columns per matrix product: below it BLAS stays on one thread (waking its threads
costs more than the product on a busy 2-core machine)."""


def sin_table(m: np.ndarray, t: np.ndarray) -> np.ndarray:
    """sin(m[:, None] * t[None, :]) (R, n) float64 for 0 <= m t <= pi, to ~1e-15 absolute.

    The Taylor series to degree 29 is separable, sum_k (c_k m^(2k+1)) t^(2k+1): one small matrix product of
    power tables instead of R * n calls of the (non-vectorised, ~12 ns) float64 sine.
    """
    m, t = np.asarray(m, np.float64), np.asarray(t, np.float64)
    mp = np.empty((len(m), _SIN_TERMS))
    tp = np.empty((_SIN_TERMS, len(t)))
    mp[:, 0], tp[0] = m, t
    m2, t2 = m * m, t * t
    for k in range(1, _SIN_TERMS):
        np.multiply(mp[:, k - 1], m2, out=mp[:, k])
        np.multiply(tp[k - 1], t2, out=tp[k])
    mp *= SIN_COEF
    out = np.empty((len(m), len(t)))
    step = max(1, _GEMM_SINGLE // max(_SIN_TERMS * len(t), 1))
    for lo in range(0, len(m), step):
        np.matmul(mp[lo:lo + step], tp, out=out[lo:lo + step])
    return out


def _design(tau: np.ndarray, seg: np.ndarray, mu_f: np.ndarray, n_knots: int, loop: bool) -> np.ndarray:
    """(K, F, n_knots) banded design for items with per-frame constants mu_f (K, F)."""
    K, F = mu_f.shape
    phi = time_pair(np.broadcast_to(tau, (K, F)), mu_f)
    A = np.zeros((K, F, n_knots))
    f = np.arange(F)
    nxt = (seg + 1) % n_knots if loop else seg + 1
    A[:, f, seg] += phi[..., 0]
    A[:, f, nxt] += phi[..., 1]
    return A


def solve_knots(b: np.ndarray, segm: Segmentation, mu: np.ndarray, loop: bool = False) -> np.ndarray:
    """Least-squares C0 knots z (K, S + 1, 4) of tracks b (K, F, 4) for constants mu (K, S), by QR.

    Open clips use a banded QR sweep (one small batched QR per segment, then back substitution); looping
    clips (cyclic band) use a dense batched QR.
    """
    if loop:
        return _solve_knots_dense(b, segm, mu, loop=True)
    phi = np.stack(segment_pair(segm, mu), axis=-1)  # (K, F, 2)
    K, F, W = b.shape
    S = segm.n_segments
    rows = np.empty((S, K, 2 + W))  # final equation of knot s: R00 z_s + R01 z_{s+1} = rhs
    carry = np.zeros((K, 1, 2 + W))
    for s in range(S):
        lo, hi = int(segm.bounds[s]), int(segm.bounds[s + 1]) if s < S - 1 else F
        block = np.concatenate([phi[:, lo:hi], b[:, lo:hi]], axis=2)
        R = np.linalg.qr(np.concatenate([carry, block], axis=1), mode="r")
        rows[s] = R[:, 0]
        carry = np.zeros((K, 1, 2 + W))
        carry[:, 0, 0] = R[:, 1, 1]
        carry[:, 0, 2:] = R[:, 1, 2:]
    z = np.empty((K, S + 1, W))
    z[:, S] = _pivot_divide(carry[:, 0, 2:], carry[:, 0, :1], S)
    for s in range(S - 1, -1, -1):
        z[:, s] = _pivot_divide(rows[s, :, 2:] - rows[s, :, 1:2] * z[:, s + 1], rows[s, :, :1], s)
    return z


def _pivot_divide(num: np.ndarray, den: np.ndarray, knot: int) -> np.ndarray:
    """num / den for the back substitution of knot ``knot``. A zero pivot means no frame determines the knot
    (e.g. a single frame): an error, not a knot silently set to 0."""
    bad = ~(np.abs(den[:, 0]) > 1e-300)
    if bad.any():
        raise PdeanimError(f"time fit: knot {knot} is not determined by any frame for {int(bad.sum())} of "
                           f"{len(bad)} tracks (zero pivot); every knot needs a frame with weight on it")
    return num / den


def _solve_knots_dense(b: np.ndarray, segm: Segmentation, mu: np.ndarray, loop: bool) -> np.ndarray:
    """Dense batched-QR knot solve (periodic knots when loop)."""
    K, F, _ = b.shape
    S = segm.n_segments
    seg, tau = segm.frame_segment(), segm.frame_tau()
    n_knots = S if loop else S + 1
    z = np.empty((K, n_knots, b.shape[2]))
    step = max(1, _CHUNK // max(F * n_knots, 1))
    for lo in range(0, K, step):
        A = _design(tau, seg, mu[lo:lo + step][:, seg], n_knots, loop)
        Q, R = np.linalg.qr(A)
        rhs = np.swapaxes(Q, 1, 2) @ b[lo:lo + step]
        try:
            z[lo:lo + step] = np.linalg.solve(R, rhs)
        except np.linalg.LinAlgError:
            z[lo:lo + step] = np.linalg.pinv(A) @ b[lo:lo + step]
    if loop:
        z = np.concatenate([z, z[:, :1]], axis=1)
    return z


def predict(z: np.ndarray, segm: Segmentation, mu: np.ndarray, spline: np.ndarray | None = None
            ) -> np.ndarray:
    """Model tracks (K, F, 4) from knots z (K, S + 1, 4) and constants mu (K, S); items flagged in
    ``spline`` (K,) bool are natural-spline tracks (:mod:`pdeanim.model.spline`, their mu 0)."""
    if spline is not None and spline.any():
        out = np.empty(z.shape[:1] + (len(segm.t),) + z.shape[2:])
        plain = ~spline
        out[spline] = predict_spline(z[spline], segm)
        if plain.any():
            out[plain] = predict(z[plain], segm, mu[plain])
        return out
    seg = segm.frame_segment()
    p0, p1 = segment_pair(segm, mu)
    out = np.take(z, seg, axis=1)  # np.take and in-place products: same values, ~3x faster than the
    out *= p0[..., None]  # fancy-indexed gathers and broadcast temporaries of the one-line form
    nxt = np.take(z, seg + 1, axis=1)
    nxt *= p1[..., None]
    out += nxt
    return out


def _segment_sum(values: np.ndarray, segm: Segmentation) -> np.ndarray:
    """(K, S) sums over the frames assigned to each segment of values (K, F).

    np.add.reduceat over the contiguous frame runs (frame_segment is sorted); a one-hot matrix product
    would be a large BLAS call that wakes BLAS threads, which costs more than it saves on a busy machine.
    """
    seg = segm.frame_segment()
    starts = np.searchsorted(seg, np.arange(segm.n_segments), "left")
    out = np.add.reduceat(values, np.minimum(starts, values.shape[1] - 1), axis=1)
    empty = starts >= np.searchsorted(seg, np.arange(segm.n_segments), "right")
    out[:, empty] = 0.0
    return out


def _free_fit_errors(b: np.ndarray, segm: Segmentation, grid: np.ndarray, loo: bool = False) -> np.ndarray:
    """(G, K, S) residual energy of per-segment fits with free end values, for every constant of the
    per-segment grid (S, G); ``loo``: the leave-one-out energy instead (each frame's residual over 1 - its
    leverage, the exact closed form for least squares; frames fitted exactly whatever the constant, as in a
    2-frame segment, count 0 for every constant, so ties keep the linear pair)."""
    if loo:
        return _loo_errors(b, segm, grid)
    K = b.shape[0]
    out = np.zeros((grid.shape[1], K, segm.n_segments))
    for s in range(segm.n_segments):
        fr = segm.frames_of(s)
        t0, t1 = segm.t[fr[0]], segm.t[fr[-1]]
        tau = (segm.t[fr] - t0) / (t1 - t0) if t1 > t0 else np.zeros(len(fr))
        B = np.moveaxis(b[:, fr], 1, 0).reshape(len(fr), -1)  # (n, K*4)
        energy = (B * B).sum(0).reshape(K, -1).sum(1)
        G = len(grid[s])
        Qs, _ = np.linalg.qr(
            time_pair(np.broadcast_to(tau, (G, len(fr))), np.repeat(grid[s][:, None], len(fr), 1))
        )
        for g in range(G):  # one thin product per constant (a stacked one wakes BLAS threads)
            cap = ((Qs[g].T @ B) ** 2).sum(0).reshape(K, -1).sum(1)
            out[g, :, s] = np.maximum(energy - cap, 0.0)
    return out


def _loo_errors(b: np.ndarray, segm: Segmentation, grid: np.ndarray) -> np.ndarray:
    """(G, K, S) leave-one-out residual energy of free per-segment fits (see :func:`_free_fit_errors`)."""
    K = b.shape[0]
    out = np.zeros((grid.shape[1], K, segm.n_segments))
    for s in range(segm.n_segments):
        fr = segm.frames_of(s)
        t0, t1 = segm.t[fr[0]], segm.t[fr[-1]]
        tau = (segm.t[fr] - t0) / (t1 - t0) if t1 > t0 else np.zeros(len(fr))
        B = np.moveaxis(b[:, fr], 1, 0).reshape(len(fr), -1)  # (n, K*4)
        G = len(grid[s])
        Qs, _ = np.linalg.qr(
            time_pair(np.broadcast_to(tau, (G, len(fr))), np.repeat(grid[s][:, None], len(fr), 1))
        )
        for g in range(G):
            Q = Qs[g]
            lev = np.einsum("na,na->n", Q, Q)
            w = np.where(lev < 1.0 - 1e-9, 1.0 / np.maximum(1.0 - lev, 1e-9) ** 2, 0.0)
            w[[0, -1]] = 0.0  # interior frames only: the in-between frames are what the constant must predict
            R = B - Q @ (Q.T @ B)
            out[g, :, s] = (w @ (R * R)).reshape(K, -1).sum(1)
    return out


def _knot_quadratic(b: np.ndarray, z: np.ndarray, segm: Segmentation) -> tuple[np.ndarray, ...]:
    """Per-frame terms of |phi0 z_s + phi1 z_s+1 - b|^2 with the knots fixed, each (K, F):
    (zz00, 2 zz01, zz11, -2 zb0, -2 zb1, bb). Knot-only products are formed per segment, then spread."""
    seg = segm.frame_segment()
    zz = _dot4(z, z)  # (K, S + 1)
    zz01 = _dot4(z[:, :-1], z[:, 1:])  # (K, S)
    zb0, zb1 = _dot4(np.take(z, seg, axis=1), b), _dot4(np.take(z, seg + 1, axis=1), b)
    return zz[:, seg], 2.0 * zz01[:, seg], zz[:, seg + 1], -2.0 * zb0, -2.0 * zb1, _dot4(b, b)


def _dot4(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sum over the last axis (length W) of x * y, in sequential order (as np.sum over a short axis)."""
    out = x[..., 0] * y[..., 0]
    for i in range(1, x.shape[-1]):
        out += x[..., i] * y[..., i]
    return out


def _fixed_knot_errors(quad: tuple[np.ndarray, ...], segm: Segmentation, mu: np.ndarray) -> np.ndarray:
    """(K, S) residual energy per segment for constants mu (K, S) with the knots fixed (see
    _knot_quadratic)."""
    p0, p1 = segment_pair(segm, mu)
    a00, a01x2, a11, b0x2, b1x2, bb = quad
    res = p0 * a00
    res += p1 * a01x2
    res += b0x2
    res *= p0
    t = p1 * a11
    t += b1x2
    t *= p1
    res += t
    res += bb
    np.maximum(res, 0.0, out=res)
    return _segment_sum(res, segm)


def _pick_grid(errs: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Index (K, S) of the best grid constant, keeping mu = 0 unless another is clearly better."""
    best = np.argmin(errs, axis=0)
    e0, eb = errs[0], np.take_along_axis(errs, best[None], 0)[0]
    return np.where(eb < e0 * (1.0 - 1e-9) - 1e-300, best, 0)


def _refine(b, z, segm, mu, lo, hi, iters):
    """Vectorised golden-section minimisation of fixed-knot segment errors over mu in [lo, hi]."""
    r = (np.sqrt(5.0) - 1.0) / 2.0
    a, bb = lo.copy(), hi.copy()
    c, d = bb - r * (bb - a), a + r * (bb - a)
    quad = _knot_quadratic(b, z, segm)
    fc, fd = _fixed_knot_errors(quad, segm, c), _fixed_knot_errors(quad, segm, d)
    for _ in range(iters):
        left = fc < fd
        a, bb = np.where(left, a, c), np.where(left, d, bb)
        c, d = np.where(left, bb - r * (bb - a), d), np.where(left, c, a + r * (bb - a))
        f_new = _fixed_knot_errors(quad, segm, np.where(left, c, d))
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
    x, fx = np.where(fc < fd, c, d), np.minimum(fc, fd)
    f_cur = _fixed_knot_errors(quad, segm, mu)
    return np.where(fx < f_cur * (1.0 - REFINE_GAIN) - 1e-300, x, mu)


LOOP_HARMONICS = 8
"""Multiples k of 2 pi over the clip tried as trig constants in looping clips (m_s = 2 pi k * segment
length)."""


def mu_caps(segm: Segmentation) -> np.ndarray:
    """(S,) largest |mu| allowed per segment (see MU_CAP_PER_INTERVAL)."""
    return MU_CAP_PER_INTERVAL * np.maximum(np.diff(segm.bounds), 1).astype(np.float64)


def _segment_grids(segm: Segmentation, grid: np.ndarray, loop: bool) -> np.ndarray:
    """(S, G) constants tried per segment, 0 first, those above the segment's cap replaced by 0. Looping clips
    replace the trig values by the multiples of 2 pi over the clip that fit below pi in the segment (the
    segment then carries an exact harmonic)."""
    grids = _uncapped_grids(segm, grid, loop)
    return np.where(np.abs(grids) <= mu_caps(segm)[:, None], grids, 0.0)


def _uncapped_grids(segm: Segmentation, grid: np.ndarray, loop: bool) -> np.ndarray:
    """(S, G) constants per segment before the caps (see :func:`_segment_grids`)."""
    if not loop:
        return np.broadcast_to(grid, (segm.n_segments, len(grid))).copy()
    pos = grid[grid > 0]
    length = np.diff(segm.segment_t)[:, None]  # (S, 1)
    harmonics = -2.0 * np.pi * np.arange(1, LOOP_HARMONICS + 1)[None, :] * length
    harmonics = np.where(-harmonics < MU_TRIG_MAX, harmonics, 0.0)
    return np.concatenate([np.zeros((segm.n_segments, 1)), np.broadcast_to(pos, (segm.n_segments, len(pos))),
                           harmonics], axis=1)


def _brackets(mu: np.ndarray, grid: np.ndarray, loop: bool, cap: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Refinement interval per (K, S): the neighbouring grid values, within the segment caps (S,); looping
    trig constants stay fixed."""
    ladder = np.sort(np.unique(grid[grid >= 0] if loop else grid))
    pos = np.searchsorted(ladder, mu)
    lo = ladder[np.clip(pos - 1, 0, len(ladder) - 1)]
    hi = ladder[np.minimum(pos + 1, len(ladder) - 1)]
    if cap is not None:
        lo, hi = (
            np.clip(lo, -np.minimum(cap, MU_TRIG_MAX), cap),
            np.clip(hi, -np.minimum(cap, MU_TRIG_MAX), cap),
        )
    if loop:
        lo, hi = np.where(mu < 0, mu, lo), np.where(mu < 0, mu, hi)
    return lo, hi


def fit_tracks(b: np.ndarray, segm: Segmentation, loop: bool = False, refine_iters: int = 8,
               rounds: int = 1, grid: np.ndarray = MU_GRID) -> tuple[np.ndarray, np.ndarray]:
    """Knots z (K, S + 1, 4) and signed constants mu (K, S) (float32-representable) for tracks b (K, F, 4).

    Grid choice on free per-segment fits, then ``rounds`` of (golden refinement with knots fixed, knot solve).
    """
    if not loop and segm.n_segments == len(segm.t) - 1:  # every frame a knot: the knots are the frames,
        return np.array(b, dtype=np.float64), np.zeros((len(b), segm.n_segments))  # exactly, whatever mu
    order = np.argsort(grid[1:]) + 1
    sorted_grid = np.concatenate([[grid[0]], grid[order]])
    seg_grid = _segment_grids(segm, sorted_grid, loop)  # (S, G)
    errs = _free_fit_errors(b, segm, seg_grid, loo=MU_CHOICE == "loo")
    idx = _pick_grid(errs, seg_grid)  # (K, S)
    mu = seg_grid[np.arange(segm.n_segments)[None, :], idx]
    lo, hi = _brackets(mu, sorted_grid, loop, mu_caps(segm)[None, :])
    mu = mu.astype(np.float32).astype(np.float64)
    z = solve_knots(b, segm, mu, loop)
    for _ in range(rounds if refine_iters > 0 else 0):
        mu = _refine(b, z, segm, mu, lo, hi, refine_iters).astype(np.float32).astype(np.float64)
        z = solve_knots(b, segm, mu, loop)
    return z, mu


CUBIC_SLACK = 1.05
"""A spline candidate keeps its spline track unless the paper's C0 track with time constants fits its frames
clearly better (residual below 1 / CUBIC_SLACK of the spline's): on few long segments the exp and trig pairs
can follow a motion that the spline cannot, while where both fit (a knot at every frame) the spline predicts
the frames in between."""


def fit_tracks_spline(b: np.ndarray, segm: Segmentation, candidates: np.ndarray, refine_iters: int = 8,
                      slack: float = CUBIC_SLACK) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(knots z (K, S + 1, 4), constants mu (K, S), spline (K,) bool) of an open clip's tracks b (K, F, 4):
    every item gets the paper's fit; the ``candidates`` (K,) bool take the natural-spline track (mu 0) where
    it fits their frames about as well (within ``slack``)."""
    z, mu = fit_tracks(b, segm, refine_iters=refine_iters)
    spline = np.zeros(len(b), bool)
    rows = np.flatnonzero(candidates)
    if len(rows) == 0:
        return z, mu, spline
    bc = b[rows]
    zc = solve_spline_knots(bc, segm)
    d0, dc = bc - predict(z[rows], segm, mu[rows]), bc - predict_spline(zc, segm)
    e0, ec = np.einsum("kfw,kfw->k", d0, d0), np.einsum("kfw,kfw->k", dc, dc)
    keep = np.ones(len(rows), bool)  # an infinite slack keeps every candidate on the spline
    if np.isfinite(slack):
        keep = ec <= slack * e0 + 1e-9 * np.einsum("kfw,kfw->k", bc, bc)
    z[rows[keep]], mu[rows[keep]] = zc[keep], 0.0
    spline[rows[keep]] = True
    return z, mu, spline
