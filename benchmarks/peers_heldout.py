"""Held-out frames in the compression benchmark: how well the clip predicts frames it was not fitted to.

Stated protocol (issue 22): keep every 4th frame (0, 4, 8, ...; the last frame only when it falls on that
grid), fit the kept frames at the SAME rel-RMS target with the CLI's defaults, and measure the frames left out
between the first and the last kept frame, against linear and Catmull-Rom interpolation of the kept frames.
Frames after the last kept one (0-3) are not in between: they are reported apart, with every method holding
the last kept frame there (as glTF players and the clip do).

The earlier protocol is a second column: every 4th frame plus the last, fitted at the tighter of 1e-3 and a
quarter of the better interpolant's held-out error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from peers_clip import load_fitted, run_fit
from peers_common import FPS, log

from pdeanim.fit.heldout import catmull_rom_interpolation, kept_frames, linear_interpolation
from pdeanim.model.metrics import bbox_diagonal, error_summary

STRIDE = 4


def fit_kept(name: str, X: np.ndarray, faces: np.ndarray, keep: np.ndarray, target: float, work: Path,
             timeout: float) -> tuple[object | None, dict]:
    """Fit the kept frames (times in seconds at FPS) with the CLI; (clip or None, fit result)."""
    src, out = work / f"{name}-kept.npz", work / f"{name}-kept.clip"
    np.savez(src, vertices=X[keep].astype(np.float32), faces=faces, times=keep / FPS)
    res = run_fit(src, out, target, timeout)
    src.unlink()
    if res.get("timeout") or not out.exists():
        log(f"{name}: held-out fit at {target:g}: no clip ({res})")
        return None, res
    parts, clip = load_fitted(out)
    out.unlink()
    res.update(kept_rel_rms=parts.report.get("rel_rms"), bytes=len(parts.topology) + len(parts.coefficients))
    return clip, res


def errors_at(X: np.ndarray, keep: np.ndarray, idx: np.ndarray, clip) -> dict[str, dict]:  # noqa: ANN001
    """rel errors at frames ``idx`` of the clip (normalised time over the kept span, held past its end),
    of linear and of Catmull-Rom interpolation of the kept frames (both held past the last kept frame)."""
    diag = bbox_diagonal(X[0])
    times = np.arange(len(X), dtype=np.float64)
    t_in = np.minimum(times[idx], keep[-1])
    kept = X[keep]
    out = {"clip": error_summary(X[idx], clip.evaluate((t_in - keep[0]) / (keep[-1] - keep[0])), diag),
           "linear": error_summary(X[idx], linear_interpolation(times[keep], kept, t_in), diag),
           "catmull_rom": error_summary(X[idx], catmull_rom_interpolation(times[keep], kept, t_in), diag)}
    return out


def heldout_row(protocol: str, target: float, keep: np.ndarray, idx: np.ndarray, errs: dict, res: dict,
                **extra) -> dict:
    """One held-out result row (rel-RMS and rel-max of each method, the clip's ratios)."""
    c, lin, cr = errs["clip"], errs["linear"], errs["catmull_rom"]
    return {"method": "heldout", "protocol": protocol, "setting": f"{protocol} rel-RMS {target:g}",
            "target": target, "kept": int(len(keep)), "measured": int(len(idx)),
            **{f"{k}_rel_rms": e["rel_rms"] for k, e in errs.items()},
            **{f"{k}_rel_max": e["rel_max"] for k, e in errs.items()},
            "clip_over_linear": c["rel_rms"] / max(lin["rel_rms"], 1e-300),
            "clip_over_catmull_rom": c["rel_rms"] / max(cr["rel_rms"], 1e-300),
            "fit_exit": res.get("rc"), "fit_s": res.get("seconds"), "kept_rel_rms": res.get("kept_rel_rms"),
            "clip_bytes": res.get("bytes"), **extra}


def stated_split(n_frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kept frames 0, 4, 8, ..., the left-out frames between the first and last kept one, all left-out)."""
    keep = np.arange(0, n_frames, STRIDE)
    left = np.setdiff1d(np.arange(n_frames), keep)
    return keep, left[left < keep[-1]], left


def stated_protocol(name: str, X: np.ndarray, faces: np.ndarray, target: float, work: Path,
                    timeout: float) -> list[dict]:
    """Every 4th frame from 0, fitted at ``target``; in-between frames, and all left-out frames."""
    keep, inside, left = stated_split(len(X))
    if len(keep) < 3 or not len(inside):
        return []
    log(f"{name}: held-out (stated) at {target:g}: {len(keep)} kept, {len(inside)} in between, "
        f"{len(left) - len(inside)} after the last kept frame")
    clip, res = fit_kept(name, X, faces, keep, target, work, timeout)
    if clip is None:
        return [{"method": "heldout", "protocol": "stated", "target": target, "failed": str(res)}]
    row = heldout_row("stated", target, keep, inside, errors_at(X, keep, inside, clip), res,
                      trailing=int(len(left) - len(inside)))
    if len(left) > len(inside):
        every = errors_at(X, keep, left, clip)
        row.update(all_clip_over_catmull_rom=every["clip"]["rel_rms"] / every["catmull_rom"]["rel_rms"],
                   all_clip_over_linear=every["clip"]["rel_rms"] / every["linear"]["rel_rms"])
    return [row]


def earlier_protocol(name: str, X: np.ndarray, faces: np.ndarray, work: Path, timeout: float) -> list[dict]:
    """Every 4th frame plus the last, fitted at min(1e-3, a quarter of the better interpolant's error)."""
    keep = kept_frames(len(X), STRIDE)
    left = np.setdiff1d(np.arange(len(X)), keep)
    if len(keep) < 3 or not len(left):
        return []
    times = np.arange(len(X), dtype=np.float64)
    diag = bbox_diagonal(X[0])
    interp = [error_summary(X[left], f(times[keep], X[keep], times[left]), diag)["rel_rms"]
              for f in (linear_interpolation, catmull_rom_interpolation)]
    target = float(min(1e-3, 0.25 * min(interp)))
    log(f"{name}: held-out (earlier protocol) at {target:.3g}")
    clip, res = fit_kept(name, X, faces, keep, target, work, timeout)
    if clip is None:
        return [{"method": "heldout", "protocol": "earlier", "target": target, "failed": str(res)}]
    return [heldout_row("earlier", target, keep, left, errors_at(X, keep, left, clip), res)]
