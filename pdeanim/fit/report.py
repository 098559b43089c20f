"""The fit report: errors of the stored clip (overall, per frame, per curve), what the search did, and the
one-line account of a missed target."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..curveset import CurveSet
from ..model.adaptive import Targets
from ..model.metrics import error_summary
from ..poses import Poses
from .options import FitOptions
from .problem import Problem
from .search import Candidate


def fit_report(p: Problem, best: Candidate, floor_d: np.ndarray, targets: Targets, options: FitOptions,
               curves: CurveSet, diag: float, poses: Poses) -> dict[str, Any]:
    """The report of the kept candidate (its stored clip's errors at every source frame)."""
    X = p.X[: poses.n_frames]
    approx = best.approx[: poses.n_frames]
    summary = error_summary(X, approx, diag)
    d = np.linalg.norm(approx.astype(np.float64) - X, axis=-1)  # (F, V)
    cid, _ = curves.curve_of_vertex(X.shape[1])
    n_c = np.bincount(cid, minlength=curves.n_curves) * len(X)
    curve_rms = np.sqrt(np.bincount(cid, (d * d).sum(0), minlength=curves.n_curves) / np.maximum(n_c, 1))
    curve_max = np.zeros(curves.n_curves)
    np.maximum.at(curve_max, cid, d.max(0))
    floor_rms = float(np.sqrt(np.mean(floor_d * floor_d)))
    met_now = bool((targets.rms is None or summary["rms"] <= targets.rms)
                   and (targets.max is None or summary["max"] <= targets.max))
    fitted = best.fitted
    return {
        **summary,
        "frames": int(poses.n_frames),
        "vertices": int(X.shape[1]),
        "curves": curves.n_curves,
        "segments": fitted.segm.n_segments,
        "segment_t": fitted.segm.segment_t.tolist(),
        "segment_frames": fitted.segm.bounds.tolist(),
        "per_frame_rms": np.sqrt(np.mean(d * d, axis=1)).tolist(),
        "per_frame_max": d.max(axis=1).tolist(),
        "per_curve_rms": curve_rms.tolist(),
        "per_curve_max": curve_max.tolist(),
        "floor_rms": floor_rms,
        "floor_rel_rms": floor_rms / diag,
        "floor_max": float(floor_d.max()),
        "float32_vs_float64_max": float(np.abs(d - best.exact[: len(d)]).max()),
        "unrounded_rms": float(np.sqrt(np.mean(best.exact[: len(d)] ** 2))),
        "unrounded_max": float(best.exact[: len(d)].max()),
        "targets": {"rms": targets.rms, "max": targets.max},
        "target_met": met_now if best.met is not None else None,
        "floor_exceeds_target": bool(best.floor_high),
        "adaptive_history": best.history,
        "options": options.to_dict(),
    }


def time_model_counts(time_model: np.ndarray, mu: np.ndarray) -> dict[str, int]:
    """How many items (curve x coordinate) use each time model: the natural spline, the paper's pairs with an
    exp or trig constant in some segment, or the paper's linear pair in every segment."""
    spline = np.asarray(time_model).reshape(-1) == 1
    bent = np.any(np.asarray(mu).reshape(len(spline), -1) != 0, axis=1) & ~spline
    return {"spline": int(spline.sum()), "pde": int(bent.sum()), "linear": int((~spline & ~bent).sum())}


def header_errors(report: dict) -> dict:
    """The error summary stored in the coefficients part's header."""
    keys = ("rms", "max", "rel_rms", "rel_max", "kg", "floor_rel_rms", "target_met", "floor_exceeds_target")
    return {k: report[k] for k in keys if k in report}


def target_shortfall(report: dict[str, Any]) -> str | None:
    """None when the fit met its targets (or had none), else one line: what was achieved vs asked, and why
    the search stopped (segment cap, spatial floor, every frame already a knot)."""
    if report.get("target_met") is not False:
        return None
    t, diag = report.get("targets") or {}, float(report.get("diagonal") or 1.0)
    asked, got = [], []
    for key in ("rms", "max"):
        if t.get(key) is not None:
            asked.append(f"{key} {t[key]:.4g} (rel {t[key] / diag:.3g})")
            got.append(f"{key} {report[key]:.4g} (rel {report[f'rel_{key}']:.3g})")
    why = []
    if report.get("segment_cap_reached"):
        why.append(f"stopped at the segment cap ({report['segments']} segments; raise max_segments)")
    if report.get("floor_exceeds_target"):
        why.append(f"the curves' spatial floor (rel rms {report.get('floor_rel_rms', 0.0):.3g}) is above the "
                   "target")
    if report.get("every_frame_a_knot"):
        why.append("every frame interval is already a segment")
    return (f"target not met: achieved {', '.join(got)}; asked {', '.join(asked)}"
            + (f"; {'; '.join(why)}" if why else ""))
