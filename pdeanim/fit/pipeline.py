"""Poses -> dynamic-PDE clip: the stages of a fit in order (space, time search, rate control, encoding,
report). The fit is measured honestly: the clip is decoded from its stored parts and evaluated at every
source frame, and those positions give the errors in the report."""

from __future__ import annotations

import time

import numpy as np

from .. import container
from ..bones.gltfskin import SkinBones
from ..clipparts import ClipParts
from ..curves.bounded import CurveErrors
from ..curveset import CurveSet
from ..model.fitcore import floor_distances, space_stage
from ..model.metrics import bbox_diagonal
from ..poses import Poses
from ..progress import Progress, sub_progress
from .bonefit import fit_with_bones
from .encode import encode
from .options import FitOptions, FitTolerances
from .problem import prepare
from .report import fit_report, time_model_counts
from .search import best_candidate
from .spacestage import space_fit
from .windowed import fit_windowed, windowed_applies


def fit_poses(poses: Poses, options: FitOptions | None = None, progress: Progress | None = None,
              curves: CurveSet | None = None, tolerances: FitTolerances | None = None,
              skin: SkinBones | None = None) -> ClipParts:
    """Fit a dynamic-PDE clip to poses (F frames, V vertices); returns both parts and a report. With
    ``options.bones`` the clip has a bone layer (``skin``: a skinned glTF input's own bones)."""
    options = (options or FitOptions()).validate()
    tol = tolerances or FitTolerances()
    t_start = time.perf_counter()
    report_progress = sub_progress(progress, 0.0, 1.0)
    if options.bones != 0:
        return fit_with_bones(poses, options, report_progress, tol, curves, skin, fit_poses)
    if windowed_applies(poses.n_frames, poses.n_vertices, options, tol):
        return fit_windowed(poses, options, report_progress, tol, curves)
    sf = space_fit(poses, options, curves, report_progress, tol)
    t_space = time.perf_counter()
    best = best_candidate(sf, options, poses, report_progress, tol)
    t_time = time.perf_counter()
    report_progress(0.97, "report")
    report = fit_report(sf, best, options, poses, tol)
    t_end = time.perf_counter()
    report.timings_s = {"curves_and_space": t_space - t_start, "time_and_encode": t_time - t_space,
                           "report": t_end - t_time, "total": t_end - t_start}
    parts = encode(sf.p, sf.curves, sf.space, best.fitted, options, poses, report.header_errors(), best.quant)
    header, arrays = container.unpack(parts.coefficients)
    report.format_version, report.knot_rank = header["format_version"], header["knot_rank"]
    report.time_models = time_model_counts(arrays["time_model"], arrays["m"].transpose(1, 2, 0))
    parts.report = {**report.to_dict(), "sizes": parts.sizes(poses.n_frames, poses.n_vertices)}
    report_progress(1.0, "done")
    return parts


def curve_errors(poses: Poses, curves: CurveSet, options: FitOptions | None = None) -> dict[str, np.ndarray]:
    """Per-curve errors of fitting poses with the given curves: {"rms": (C,), "max": (C,), "floor_rms": (C,)}.

    For error-bounded curve extraction: fit, then read which curves stay above a target.
    """
    parts = fit_poses(poses, options, curves=curves)
    r = parts.report
    p = prepare(poses, options or FitOptions(), curves)
    K, N = p.Y.shape[1], p.Y.shape[2]
    space = space_stage(p.Y, p.u.reshape(K, N), np.repeat(p.mask, 3, axis=0))
    fd = floor_distances(space, p.slots)
    cid, _ = curves.curve_of_vertex(p.X.shape[1])
    n_c = np.bincount(cid, minlength=curves.n_curves) * len(fd)
    floor_rms = np.sqrt(np.bincount(cid, (fd * fd).sum(0), minlength=curves.n_curves) / np.maximum(n_c, 1))
    return {"rms": np.asarray(r["per_curve_rms"]), "max": np.asarray(r["per_curve_max"]),
            "floor_rms": floor_rms}


def fit_errors(poses: Poses, options: FitOptions | None = None) -> CurveErrors:
    """Per-curve relative RMS of the model's fit (:func:`curve_errors`), for error-bounded curves."""
    diag = bbox_diagonal(np.asarray(poses.vertices[0], np.float64))
    return lambda curves: np.asarray(curve_errors(poses, curves, options)["rms"]) / diag
