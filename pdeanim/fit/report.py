"""The fit report: errors of the stored clip (overall, per frame, per curve), what the search did, and the
one-line account of a missed target."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..clipparts import FORMAT_VERSION
from ..model.metrics import error_summary
from ..poses import Poses
from .options import FitOptions, FitTolerances
from .search import Candidate
from .spacestage import SpaceFit


@dataclass
class FitReport:
    """The report of a fit, built alike by the in-memory and the windowed fit: the stored clip's errors at
    every source frame (overall, per frame, per curve), the floors, the targets and what the search and the
    rate control did. :meth:`to_dict` gives what ``ClipParts.report`` holds (JSON)."""

    rms: float
    max: float
    rel_rms: float | None
    rel_max: float | None
    kg: float | None
    diagonal: float | None
    frames: int
    vertices: int
    curves: int
    segments: int
    segment_t: list[float]
    segment_frames: list[int]
    per_frame_rms: list[float]
    per_frame_max: list[float]
    per_curve_rms: list[float]
    per_curve_max: list[float]
    floor_rms: float
    floor_rel_rms: float | None
    floor_max: float
    float32_vs_float64_max: float | None
    unrounded_rms: float
    unrounded_max: float
    targets: dict[str, float | None]
    target_met: bool | None
    floor_exceeds_target: bool
    adaptive_history: list[dict]
    options: dict[str, Any]
    curve_points: int | None
    curve_splits: int
    dense_fit: bool
    segment_cap_reached: bool
    every_frame_a_knot: bool
    quantisation_tolerance: float | None
    quantisation_knot_rms: float | None
    quantisation_knot_cap: float | None
    rate_control: list[dict]
    tolerances: dict[str, Any]
    format_version: str = FORMAT_VERSION
    knot_rank: int = 0
    time_models: dict[str, int] = field(default_factory=dict)
    timings_s: dict[str, float] | None = None
    windows: list[dict] | None = None  # a windowed fit's windows; with it curve_frames and gram_floor_rel_rms
    curve_frames: int | None = None
    gram_floor_rel_rms: float | None = None

    def header_errors(self) -> dict[str, Any]:
        """The error summary stored in the coefficients part's header."""
        return {k: getattr(self, k) for k in HEADER_ERRORS}

    def to_dict(self) -> dict[str, Any]:
        """The report as a dict (a windowed fit's adds ``windowed``, ``windows``, ``curve_frames`` and
        ``gram_floor_rel_rms``; ``timings_s`` where timed)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        if self.timings_s is None:
            del out["timings_s"]
        if self.windows is None:
            for key in ("windows", "curve_frames", "gram_floor_rel_rms"):
                del out[key]
        else:
            out["windowed"] = True
        return out


HEADER_ERRORS = ("rms", "max", "rel_rms", "rel_max", "kg", "floor_rel_rms", "target_met",
                 "floor_exceeds_target")
"""The report's keys stored in the coefficients part's header (``errors``)."""


def fit_report(sf: SpaceFit, best: Candidate, options: FitOptions, poses: Poses, tol: FitTolerances
               ) -> FitReport:
    """The report of an in-memory fit's kept candidate (its stored clip's errors at every source frame)."""
    p, floor_d, targets, curves, diag = sf.p, sf.floor_d, sf.targets, sf.curves, sf.diag
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
    fitted = best.fitted
    return FitReport(
        **summary,
        frames=int(poses.n_frames), vertices=int(X.shape[1]), curves=curves.n_curves,
        segments=fitted.segm.n_segments, segment_t=fitted.segm.segment_t.tolist(),
        segment_frames=fitted.segm.bounds.tolist(),
        per_frame_rms=np.sqrt(np.mean(d * d, axis=1)).tolist(), per_frame_max=d.max(axis=1).tolist(),
        per_curve_rms=curve_rms.tolist(), per_curve_max=curve_max.tolist(),
        floor_rms=floor_rms, floor_rel_rms=floor_rms / diag, floor_max=float(floor_d.max()),
        float32_vs_float64_max=float(np.abs(d - best.exact[: len(d)]).max()),
        unrounded_rms=float(np.sqrt(np.mean(best.exact[: len(d)] ** 2))),
        unrounded_max=float(best.exact[: len(d)].max()),
        targets={"rms": targets.rms, "max": targets.max},
        target_met=targets.meets(summary["rms"], summary["max"]) if best.met is not None else None,
        floor_exceeds_target=bool(best.floor_high), adaptive_history=best.history, options=options.to_dict(),
        curve_points=sf.curve_points, curve_splits=sf.splits, dense_fit=best.dense is not None,
        segment_cap_reached=bool(best.cap) and not best.meets,
        every_frame_a_knot=bool(best.unsplittable) and not best.meets,
        quantisation_tolerance=best.quant.tolerance, quantisation_knot_rms=best.quant.knot_rms,
        quantisation_knot_cap=best.quant.knot_cap, rate_control=best.trials, tolerances=tol.to_dict())


def time_model_counts(time_model: np.ndarray, mu: np.ndarray) -> dict[str, int]:
    """How many items (curve x coordinate) use each time model: the natural spline, the paper's pairs with an
    exp or trig constant in some segment, or the paper's linear pair in every segment."""
    spline = np.asarray(time_model).reshape(-1) == 1
    bent = np.any(np.asarray(mu).reshape(len(spline), -1) != 0, axis=1) & ~spline
    return {"spline": int(spline.sum()), "pde": int(bent.sum()), "linear": int((~spline & ~bent).sum())}


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
