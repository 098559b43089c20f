"""The time half of a fit: the error-driven segment search (or fixed or dense segments), each candidate
rounded and measured as stored, and the choice between candidates."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.adaptive import fit_adaptive
from ..model.fitcore import TimeStage, model_distances, time_stage
from ..model.segments import Segmentation, normalised_times, uniform_segmentation
from ..poses import Poses
from ..progress import Progress, sub_progress
from .encode import Quantisation, encode
from .options import FitOptions, FitTolerances
from .problem import meets, stored_distances
from .ratecontrol import quantised, soft_max
from .spacestage import SpaceFit


@dataclass
class Candidate:
    """One time fit and its stored clip."""

    dense: int | None  # the segment count of a dense fit, None for the error-driven or fixed one
    fitted: TimeStage
    met: bool | None
    floor_high: bool
    history: list
    cap: bool
    unsplittable: bool
    exact: np.ndarray  # (F, V) distances of the unrounded fit
    quant: Quantisation
    approx: np.ndarray  # (F, V, 3) float32 positions of the stored clip
    size: int
    meets: bool


def candidate(sf: SpaceFit, options: FitOptions, poses: Poses, progress: Progress | None,
              tol: FitTolerances, dense: int | None = None) -> Candidate:
    """A time fit (error-driven, fixed segments, or ``dense`` evenly spaced segments) rounded and measured on
    the targets."""
    p = sf.p
    if options.segments or dense:
        every = dense is not None and dense >= len(p.t) - 1
        segm = Segmentation(np.arange(len(p.t)), normalised_times(p.t)) if every else uniform_segmentation(
            p.t, options.segments or dense)
        fitted, met, floor_high, history = time_stage(sf.space, segm, options.loop), None, False, []
        cap = unsplittable = False
    else:
        res = fit_adaptive(sf.space, Segmentation(np.array([0, len(p.t) - 1]), p.t), sf.targets,
                           lambda ts: model_distances(sf.space, ts, p.slots), sf.floor_d,
                           min(options.max_segments, len(p.t) - 1), options.loop, progress)
        fitted, met, floor_high, history = res.time, res.met, res.floor_exceeds_target, res.history
        cap, unsplittable = res.cap_reached, res.unsplittable
    exact = model_distances(sf.space, fitted, p.slots)
    quant, approx, size = quantised(sf, fitted, options, poses, exact, tol)
    ok = meets(sf.targets, stored_distances(p, approx, poses.n_frames))
    return Candidate(dense, fitted, ok if dense else met, floor_high, history, cap, unsplittable, exact,
                     quant, approx, size, ok)


def best_candidate(sf: SpaceFit, options: FitOptions, poses: Poses, progress: Progress | None,
                   tol: FitTolerances) -> Candidate:
    """The error-driven (or fixed-segment) candidate, or the dense one where it is tried and preferred (see
    tol.dense_from); ``progress`` is the whole fit's (this stage reports from 0.1 to 0.86)."""
    best = candidate(sf, options, poses, sub_progress(progress, 0.1, 0.85), tol)
    frames = len(sf.p.t) - 1
    dense = min(frames, options.max_segments)
    if (not options.segments and best.meets
            and tol.dense_from * frames <= best.fitted.segm.n_segments < dense):
        if progress is not None:
            progress(0.86, f"dense fit ({dense} segments)")
        cand = candidate(sf, options, poses, None, tol, dense)
        if cand.meets and preferred(sf, options, poses, cand, best, tol):
            best = cand
    return best


def preferred(sf: SpaceFit, options: FitOptions, poses: Poses, a: Candidate, b: Candidate,
              tol: FitTolerances) -> bool:
    """Whether candidate ``a`` is kept over ``b``: the one within the soft max bound of an RMS target if only
    one is, else the smaller, or of two close in size the one with a clearly lower max error, else the
    smaller at the final zstd level."""
    worst = [float(stored_distances(sf.p, c.approx, poses.n_frames).max()) for c in (a, b)]
    soft = soft_max(sf.targets, tol)
    if soft is not None and (worst[0] <= soft) != (worst[1] <= soft):
        return worst[0] <= soft
    if abs(a.size - b.size) > tol.close_sizes * min(a.size, b.size):
        return a.size < b.size
    if worst[0] < tol.clearly_lower_max * worst[1] or worst[1] < tol.clearly_lower_max * worst[0]:
        return worst[0] < worst[1]

    def final(c: Candidate) -> int:
        parts = encode(sf.p, sf.curves, sf.space, c.fitted, options, poses, None, c.quant)
        return len(parts.topology) + len(parts.coefficients)

    return final(a) < final(b)
