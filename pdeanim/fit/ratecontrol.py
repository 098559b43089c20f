"""Rate control: how coarsely the fitted clip is rounded. The knots' RMS budget grows (or is bisected) until
the stored clip's RMS error lands in a band just under an RMS target; a curve on which some vertex strays past
the max bound (a max target, or the soft bound of an RMS target) gets finer knot steps of its own. Every trial
is measured on the stored clip (docs/compression.md, "Rate control")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import container
from ..model.adaptive import Targets
from ..model.clipformat import TRIAL_LEVEL
from ..model.fitcore import TimeStage
from ..model.quantise import power_of_two_step
from ..poses import Poses
from .encode import Quantisation, decode, encode, stored_clip
from .options import FitOptions, FitTolerances
from .problem import meets, stored_distances
from .spacestage import SpaceFit


def first_quantisation(targets: Targets, exact: np.ndarray, tol: FitTolerances) -> Quantisation:
    """The first rounding tried: a share of the tightest target per coordinate; with an RMS target, the knots
    get most of what the unrounded fit (distances ``exact`` (F, V)) leaves of it, moving no vertex coordinate
    by more than tol.knot_cap times that budget."""
    goals = [g for g in (targets.rms, targets.max) if g is not None]
    if not goals:
        return Quantisation()
    tolerance = tol.quant_share * min(goals)
    if targets.rms is None:
        return Quantisation(tolerance)
    rest_step = power_of_two_step(tolerance)
    spare = tol.quant_budget * (targets.rms**2 - float(np.mean(exact * exact))) - rest_step**2 / 4
    if spare <= tolerance**2:
        return Quantisation(tolerance)
    knot_rms = float(np.sqrt(spare))
    return Quantisation(tolerance, knot_rms, tol.knot_cap * knot_rms)


def quantised(sf: SpaceFit, fitted: TimeStage, options: FitOptions, poses: Poses, exact: np.ndarray,
              tol: FitTolerances, trials: list[dict] | None = None) -> tuple[Quantisation, np.ndarray, int]:
    """(rounding, decoded positions (F, V, 3), stored bytes at the trial zstd level) of the clip of a fit.
    The rounding is searched on the stored clip with the knots on the shared tracks its first encoding chose
    (:func:`_rounding`; each trial is appended to ``trials``); then the rank is chosen again by size for the
    rounding found, kept where that still meets the targets."""
    quant = _rounding(sf, fitted, options, poses, exact, tol, trials)
    bound = max_bound(sf.targets, tol)
    F = poses.n_frames
    for rank in (None, quant.rank):
        parts = encode(sf.p, sf.curves, sf.space, fitted, options, poses, None, replace(quant, rank=rank),
                       TRIAL_LEVEL)
        clip = decode(parts)
        approx = clip.evaluate(clip.frame_t())
        chosen = int(container.unpack(parts.coefficients)[0]["knot_rank"])
        d = stored_distances(sf.p, approx, F)
        reachable = quant.tolerance is not None and meets(sf.targets, exact[:F])
        if chosen == quant.rank or not reachable or (
                meets(sf.targets, d) and (bound is None or _over(sf, d, exact, bound) is None)):
            break
    return replace(quant, rank=chosen), approx, len(parts.topology) + len(parts.coefficients)


def _rounding(sf: SpaceFit, fitted: TimeStage, options: FitOptions, poses: Poses, exact: np.ndarray,
              tol: FitTolerances, trials: list[dict] | None) -> Quantisation:
    """The coarsest rounding found whose stored clip meets the targets, with its RMS error in
    [tol.quant_fill, 1] of an RMS target where the trials reach it, and no curve past the max bound that the
    unrounded fit kept within it; the knots on the number of shared tracks that the first rounding's
    smallest encoding has."""
    p, F, targets = sf.p, poses.n_frames, sf.targets
    quant = first_quantisation(targets, exact[:F], tol)
    if quant.tolerance is None or not meets(targets, exact[:F]):
        return quant  # nothing to round for, or a target the fit itself misses
    bound = max_bound(targets, tol)
    first = encode(p, sf.curves, sf.space, fitted, options, poses, None, quant, TRIAL_LEVEL)
    quant = replace(quant, rank=int(container.unpack(first.coefficients)[0]["knot_rank"]))
    good, bad = None, None  # the coarsest budget that met the targets; the finest one that missed the RMS
    for _ in range(tol.quant_retries + 1):
        clip = stored_clip(p, sf.curves, sf.space, fitted, options, poses, quant)
        d = stored_distances(p, clip.evaluate(clip.frame_t()), F)
        if trials is not None:
            trials.append(_trial(targets, quant, d))
        rms = float(np.sqrt(np.mean(d * d)))
        rms_missed = targets.rms is not None and rms > targets.rms
        over = None if bound is None or rms_missed else _over(sf, d, exact, bound)
        if over is not None:  # finer steps on the curves past the bound, the budget kept
            quant = quant.refined(over, sf.curves.n_curves)
            continue
        if meets(targets, d):
            good = quant
            if quant.knot_rms is None or rms >= tol.quant_fill * targets.rms:
                return good
        else:
            bad = quant
        if quant.knot_rms is None:
            quant = quant.finer()
            continue
        if good is None:  # the first budget missed: shrink towards the aim
            quant = quant.coarser(growth(rms**2, float(np.mean(exact[:F] ** 2)), targets.rms, tol))
            continue
        if bad is None:
            factor = growth(rms**2, float(np.mean(exact[:F] ** 2)), targets.rms, tol)
        else:
            gap = bad.knot_rms / good.knot_rms  # bisect (in log) between the last met and the first missed
            if gap < tol.bisect_until:
                return good
            factor = float(np.sqrt(gap))
        quant = replace(good.coarser(factor), refine=quant.refine)  # the refinements found so far stay
    return good or quant


def _over(sf: SpaceFit, d: np.ndarray, exact: np.ndarray, bound: float) -> np.ndarray | None:
    """Indices of the curves on which a vertex of the stored clip is past the max bound while the unrounded
    fit kept it within (the rounding's doing), or None."""
    cid = sf.p.curve_of
    C = sf.curves.n_curves
    stored, unrounded = np.zeros(C), np.zeros(C)
    np.maximum.at(stored, cid, d.max(axis=0, initial=0.0))
    np.maximum.at(unrounded, cid, exact[: len(d)].max(axis=0, initial=0.0))
    over = np.flatnonzero((stored > bound) & (unrounded <= bound))
    return over if len(over) else None


def _trial(targets: Targets, quant: Quantisation, d: np.ndarray) -> dict:
    """One rate-control trial for the report: the knots' RMS budget, how many curves have refined steps, and
    the stored clip's RMS and max error over the targets (an RMS target's when there is no max target)."""
    rms, worst = float(np.sqrt(np.mean(d * d))), float(d.max(initial=0.0))
    return {"knot_rms": quant.knot_rms, "knot_rank": quant.rank,
            "refined_curves": 0 if quant.refine is None else int(np.any(quant.refine > 0, axis=1).sum()),
            "rms_over_target": rms / targets.rms if targets.rms else None,
            "max_over_target": worst / (targets.max or targets.rms or 1.0)}


def max_bound(targets: Targets, tol: FitTolerances) -> float | None:
    """The most any vertex may be off: a max target, else the soft bound of an RMS target
    (tol.soft_max_ratio), else None."""
    if targets.max is not None:
        return targets.max
    if tol.soft_max_ratio is None or targets.rms is None:
        return None
    return tol.soft_max_ratio * targets.rms


def growth(stored: float, exact: float, target: float, tol: FitTolerances) -> float:
    """Factor on the knots' budget that should bring the stored mean square error ``stored`` to tol.quant_aim
    of the RMS ``target``, the rounding adding ``stored - exact`` (proportional to the budget squared): at
    least tol.growth_min (or at most its inverse, to shrink) and within tol.growth_max of 1."""
    added = stored - exact
    if added <= 0:
        return tol.growth_max
    aim = max((tol.quant_aim * target) ** 2 - exact, 0.0)
    raw = np.sqrt(aim / added)
    if raw >= 1.0:
        return float(np.clip(raw, tol.growth_min, tol.growth_max))
    return float(np.clip(raw, 1.0 / tol.growth_max, 1.0 / tol.growth_min))
