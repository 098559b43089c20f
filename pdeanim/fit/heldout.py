"""Held-out frame test: fit from every k-th frame, evaluate at the frames left out, compare with linear
interpolation of the same kept frames (the question the paper claims but never measures), with Catmull-Rom
interpolation of them, and with linear interpolation of as many evenly spaced kept frames as fit in the
clip's bytes (both parts).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..curveset import CurveSet
from ..errors import ParameterError
from ..model.metrics import bbox_diagonal, error_summary
from ..poses import Poses, make_poses
from .encode import decode
from .options import FitOptions, FitTolerances
from .pipeline import fit_poses


def kept_frames(n_frames: int, k: int) -> np.ndarray:
    """Every k-th frame index, always including the last one (so nothing is extrapolated)."""
    if k < 2:
        raise ParameterError(f"held-out stride k must be >= 2, got {k}")
    idx = np.arange(0, n_frames, k)
    return idx if idx[-1] == n_frames - 1 else np.append(idx, n_frames - 1)


def linear_interpolation(times_kept: np.ndarray, frames_kept: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of frames (K, V, 3) at kept times onto times (M,): (M, V, 3)."""
    j = np.clip(np.searchsorted(times_kept, times, side="right") - 1, 0, len(times_kept) - 2)
    t0, t1 = times_kept[j], times_kept[j + 1]
    w = ((times - t0) / np.where(t1 > t0, t1 - t0, 1.0))[:, None, None]
    return (1.0 - w) * frames_kept[j] + w * frames_kept[j + 1]


def catmull_rom_interpolation(
    times_kept: np.ndarray, frames_kept: np.ndarray, times: np.ndarray
) -> np.ndarray:
    """Centripetal-free (uniform-tangent) Catmull-Rom interpolation of frames (K, V, 3) at kept times onto
    times (M,): cubic Hermite with tangents from the neighbouring kept frames (one-sided at the ends)."""
    tk = np.asarray(times_kept, np.float64)
    P = np.asarray(frames_kept, np.float64)
    K = len(tk)
    if K < 3:
        return linear_interpolation(tk, P, times)
    j = np.clip(np.searchsorted(tk, times, side="right") - 1, 0, K - 2)
    prev, nxt = np.maximum(j - 1, 0), np.minimum(j + 2, K - 1)
    h = tk[j + 1] - tk[j]
    m0 = (P[j + 1] - P[prev]) * (h / np.where(tk[j + 1] > tk[prev], tk[j + 1] - tk[prev], 1.0))[:, None, None]
    m1 = (P[nxt] - P[j]) * (h / np.where(tk[nxt] > tk[j], tk[nxt] - tk[j], 1.0))[:, None, None]
    s = ((times - tk[j]) / np.where(h > 0, h, 1.0))[:, None, None]
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * P[j] + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * P[j + 1]
            + (s3 - s2) * m1)


def heldout_comparison(poses: Poses, k: int, options: FitOptions | None = None,
                       curves: CurveSet | None = None, tolerances: FitTolerances | None = None
                       ) -> dict[str, Any]:
    """Errors at the left-out frames of the PDE clip fitted on every k-th frame vs linear interpolation."""
    keep = kept_frames(poses.n_frames, k)
    out = np.setdiff1d(np.arange(poses.n_frames), keep)
    if len(out) == 0:
        raise ParameterError("no frames are left out; use more frames or a larger k")
    sub = make_poses(poses.vertices[keep], poses.faces, poses.times[keep])
    parts = fit_poses(sub, options, curves=curves, tolerances=tolerances)
    clip = decode(parts)
    times = np.asarray(poses.times, np.float64)
    t_norm = (times - times[0]) / (times[-1] - times[0])
    truth = poses.vertices[out]
    diag = bbox_diagonal(poses.vertices[0])
    pde = error_summary(truth, clip.evaluate(t_norm[out]), diag)
    kept64 = poses.vertices[keep].astype(np.float64)
    lin = error_summary(truth, linear_interpolation(times[keep], kept64, times[out]), diag)
    cr = error_summary(truth, catmull_rom_interpolation(times[keep], kept64, times[out]), diag)
    n_eq = int(
        np.clip((len(parts.coefficients) + len(parts.topology)) // (poses.n_vertices * 12), 2, len(keep))
    )
    eq = keep[np.unique(np.round(np.linspace(0, len(keep) - 1, n_eq)).astype(int))]
    lin_eq = error_summary(
        truth, linear_interpolation(times[eq], poses.vertices[eq].astype(np.float64), times[out]), diag
    )
    return {
        "k": int(k),
        "kept_frames": int(len(keep)),
        "heldout_frames": int(len(out)),
        "pde": pde,
        "linear": lin,
        "catmull_rom": cr,
        "linear_equal_bytes": lin_eq,
        "linear_equal_bytes_frames": int(len(eq)),
        "fit_report": {key: parts.report[key] for key in ("rel_rms", "segments", "curves", "target_met")},
        "coefficients_bytes": len(parts.coefficients),
        "kept_raw_bytes": int(len(keep) * poses.n_vertices * 12),
    }
