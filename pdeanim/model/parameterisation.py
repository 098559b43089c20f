"""Curve parameter u in [0, 1] for every point of every curve: chord length (default) or the paper's Eq. 9-10.

Curves arrive padded (see :meth:`pdeanim.curveset.CurveSet.padded`): points (..., C, N, 3) with a (C, N) mask.
The result is always per coordinate, u (C, 3, N), so both modes feed the same fit; chord length repeats one
u over x, y, z. Padding entries repeat the curve's last u.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError

PARAM_MODES = ("chord", "paper")


def chord_parameters(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Normalised cumulative chord length per curve.

    points : (C, N, 3) or (F, C, N, 3) float (frames are averaged); mask : (C, N) bool.
    Returns (C, N) float64 in [0, 1]; 1-point curves get 0, zero-length curves uniform spacing.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 3:
        p = p[None]
    seg = np.linalg.norm(np.diff(p, axis=2), axis=-1) * mask[None, :, 1:]  # (F, C, N-1)
    cum = np.concatenate([np.zeros(seg.shape[:2] + (1,)), np.cumsum(seg, axis=-1)], axis=-1)
    total = cum[..., -1:]
    n = mask.sum(axis=1)  # (C,)
    idx = np.arange(mask.shape[1])[None, :]
    uniform = np.minimum(idx, (n - 1)[:, None]) / np.maximum(n - 1, 1)[:, None]  # (C, N)
    ok = total > 1e-12 * (1.0 + np.abs(p).max())
    u = np.where(ok, cum / np.where(ok, total, 1.0), uniform[None])
    return np.clip(u.mean(axis=0), 0.0, 1.0)


def paper_parameters(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The paper's per-coordinate normalised positions (Eq. 9-10), averaged over frames.

    points : (C, N, 3) or (F, C, N, 3); mask : (C, N) bool. Returns (C, 3, N) float64. A coordinate that is
    flat on a curve (max == min, where Eq. 10 divides by zero) falls back to chord length, so no NaN.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 3:
        p = p[None]
    m = mask[None, :, :, None]
    lo = np.where(m, p, np.inf).min(axis=2, keepdims=True)
    hi = np.where(m, p, -np.inf).max(axis=2, keepdims=True)
    span = hi - lo
    scale = 1e-9 * (1.0 + np.abs(p).max())
    flat = span <= scale  # (F, C, 1, 3)
    u = np.where(flat, 0.0, (p - lo) / np.where(flat, 1.0, span))
    chord = chord_parameters(p, mask)  # (C, N)
    flat_any = flat.mean(axis=0)[:, 0, :] > 0.5  # (C, 3) flat in most frames
    u = np.moveaxis(u.mean(axis=0), -1, 1)  # (C, 3, N)
    u = np.where(flat_any[:, :, None], chord[:, None, :], u)
    return np.clip(u, 0.0, 1.0)


def curve_parameters(points: np.ndarray, mask: np.ndarray, mode: str = "chord") -> np.ndarray:
    """u (C, 3, N) float64 for the given mode ("chord" or "paper"); points (C, N, 3) or (F, C, N, 3)."""
    if mode == "chord":
        u = chord_parameters(points, mask)
        return np.repeat(u[:, None, :], 3, axis=1)
    if mode == "paper":
        return paper_parameters(points, mask)
    raise ParameterError(f"param_mode must be one of {PARAM_MODES}, got {mode!r}")
