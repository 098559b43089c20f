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
from .problem import stored_distances
from .ratecontrol import max_bound, quantised
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
    trials: list[dict]  # the rate control's trials (ratecontrol._trial)
    exact: np.ndarray  # (F, V) distances of the unrounded fit
    quant: Quantisation
    approx: np.ndarray  # (F, V, 3) float32 positions of the stored clip
    size: int
    meets: bool


def candidate(sf: SpaceFit, options: FitOptions, poses: Poses, progress: Progress | None,
              tol: FitTolerances, dense: int | None = None, search_cap: int | None = None,
              start: np.ndarray | None = None) -> Candidate:
    """A time fit (error-driven up to ``search_cap`` segments, fixed segments, or ``dense`` evenly spaced
    segments: a knot at every frame when there are enough) rounded and measured on the targets. ``start``:
    the boundaries (frames) the error-driven search starts from and keeps (default: the first and last)."""
    return rounded(sf, options, poses, tol, dense,
                   *time_fit(sf, options, progress, dense, search_cap, start))


def time_fit(sf: SpaceFit, options: FitOptions, progress: Progress | None, dense: int | None = None,
             search_cap: int | None = None, start: np.ndarray | None = None) -> tuple:
    """The unrounded time fit of :func:`candidate`: (fitted, met, floor_high, history, cap, unsplittable)."""
    p = sf.p
    frames = len(p.t) - 1
    if options.segments or dense:
        every = dense is not None and dense >= frames
        segm = Segmentation(np.arange(len(p.t)), normalised_times(p.t)) if every else uniform_segmentation(
            p.t, options.segments or dense)
        fitted, met, floor_high, history = time_stage(sf.space, segm, options.loop), None, False, []
        cap, unsplittable = dense is not None and not every, every
    else:
        bounds = np.array([0, frames]) if start is None else np.asarray(start, np.int64)
        res = fit_adaptive(sf.space, Segmentation(bounds, p.t), sf.targets,
                           lambda ts: model_distances(sf.space, ts, p.slots), sf.floor_d,
                           min(options.max_segments, frames, (search_cap or frames) + len(bounds) - 2),
                           options.loop, progress, None if start is None else bounds)
        fitted, met, floor_high, history = res.time, res.met, res.floor_exceeds_target, res.history
        cap, unsplittable = res.cap_reached, res.unsplittable
    return fitted, met, floor_high, history, cap, unsplittable


def rounded(sf: SpaceFit, options: FitOptions, poses: Poses, tol: FitTolerances, dense: int | None,
            fitted: TimeStage, met: bool | None, floor_high: bool, history: list, cap: bool,
            unsplittable: bool) -> Candidate:
    """:func:`candidate` of an unrounded :func:`time_fit`: rounded by the rate control and measured."""
    p = sf.p
    exact = model_distances(sf.space, fitted, p.slots)
    trials: list[dict] = []
    quant, approx, size = quantised(sf, fitted, options, poses, exact, tol, trials)
    ok = sf.targets.met_by(stored_distances(p, approx, poses.n_frames))
    if dense:  # a missed target is the dense fit's only when the spatial floor is not above it
        met = ok
        floor_high = not ok and _floor_above(sf)
    return Candidate(dense, fitted, met, floor_high, history, cap, unsplittable, trials, exact, quant, approx,
                     size, ok)


def _floor_above(sf: SpaceFit) -> bool:
    """Whether the curves' spatial floor alone exceeds a target (no time fit can then meet it)."""
    return not sf.targets.met_by(sf.floor_d)


def best_candidate(sf: SpaceFit, options: FitOptions, poses: Poses, progress: Progress | None,
                   tol: FitTolerances, start: np.ndarray | None = None, lazy: bool = False) -> Candidate:
    """The fixed-segment candidate; or of the error-driven one (searched up to tol.search_share of the frame
    intervals when the dense fit is tried; from the boundaries ``start``, see :func:`candidate`) and the dense
    one (tol.dense_fit), the one that meets the targets, the preferred one where both do, else the one closer
    to them. ``progress`` is the whole fit's (this stage reports from 0.1 to 0.86). ``lazy`` (a window of a
    windowed fit): a search that missed the targets unrounded is not rounded when the dense candidate meets
    them (rounding only adds error, so it would lose to the dense one: its rate control is skipped)."""
    if options.segments:
        return candidate(sf, options, poses, sub_progress(progress, 0.1, 0.85), tol)
    frames = len(sf.p.t) - 1
    dense = min(frames, options.max_segments)
    cap = min(dense, max(1, int(np.ceil(tol.search_share * frames)))) if tol.dense_fit else dense
    found = time_fit(sf, options, sub_progress(progress, 0.1, 0.85), search_cap=cap, start=start)
    full = None
    if lazy and tol.dense_fit and found[1] is not None and not found[1] and found[0].segm.n_segments < dense:
        if progress is not None:
            progress(0.86, f"dense fit ({dense} segments)")
        full = candidate(sf, options, poses, None, tol, dense)
        if full.meets:
            return full
    search = rounded(sf, options, poses, tol, None, *found)
    if not tol.dense_fit or search.fitted.segm.n_segments >= dense:
        return search
    if full is None:
        if progress is not None:
            progress(0.86, f"dense fit ({dense} segments)")
        full = candidate(sf, options, poses, None, tol, dense)
    if search.meets and full.meets:
        return full if preferred(sf, options, poses, full, search, tol) else search
    if search.meets or full.meets:
        return search if search.meets else full
    return min((search, full), key=lambda c: _excess(sf, poses, c))


def _excess(sf: SpaceFit, poses: Poses, c: Candidate) -> float:
    """How far a candidate's stored clip is from its targets: the larger of its RMS and max over them."""
    d = stored_distances(sf.p, c.approx, poses.n_frames)
    return float(sf.targets.excess(float(np.sqrt(np.mean(d * d))), float(d.max(initial=0.0))))


def preferred(sf: SpaceFit, options: FitOptions, poses: Poses, a: Candidate, b: Candidate,
              tol: FitTolerances) -> bool:
    """Whether candidate ``a`` is kept over ``b``: the one within the soft max bound of an RMS target if only
    one is, else the smaller, or of two close in size the one with a clearly lower max error, else the
    smaller at the final zstd level."""
    worst = [float(stored_distances(sf.p, c.approx, poses.n_frames).max()) for c in (a, b)]
    soft = max_bound(sf.targets, tol)
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
