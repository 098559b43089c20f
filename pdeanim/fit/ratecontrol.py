"""Rate control: how coarsely the fitted clip is rounded. The knots' RMS budget grows (or is bisected) until
the stored clip's RMS error lands in a band just under an RMS target; a curve on which some vertex strays past
the max bound (a max target, or the soft bound of an RMS target) gets finer knot steps of its own. Every trial
is measured on the stored clip (docs/compression.md, "Rate control")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from .. import container
from ..model.adaptive import Targets
from ..model.clipformat import SHARED_KEY, TRIAL_LEVEL
from ..model.fitcore import TimeStage
from ..model.quantise import power_of_two_step
from ..poses import Poses
from .encode import Quantisation, decode, encode, stored_clip
from .options import FitOptions, FitTolerances
from .problem import stored_distances
from .spacestage import SpaceFit


def first_quantisation(targets: Targets, unrounded_ms: float, tol: FitTolerances) -> Quantisation:
    """The first rounding tried: a share of the tightest target per coordinate; with an RMS target, the knots
    get most of what the unrounded fit (its mean square distance ``unrounded_ms``) leaves of it, moving no
    vertex coordinate by more than tol.knot_cap times that budget."""
    goals = [g for g in (targets.rms, targets.max) if g is not None]
    if not goals:
        return Quantisation()
    tolerance = tol.quant_share * min(goals)
    if targets.rms is None:
        return Quantisation(tolerance)
    rest_step = power_of_two_step(tolerance)
    spare = tol.quant_budget * (targets.rms**2 - unrounded_ms) - rest_step**2 / 4
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
    for rank in (None, quant.rank) if tol.knot_basis else (0,):
        parts = encode(sf.p, sf.curves, sf.space, fitted, options, poses, None, replace(quant, rank=rank),
                       TRIAL_LEVEL)
        clip = decode(parts)
        approx = clip.evaluate(clip.frame_t())
        chosen = stored_rank(parts.coefficients)
        found = Errors.of(stored_distances(sf.p, approx, F), sf.p.curve_of, sf.curves.n_curves)
        unrounded = Errors.of(exact[:F], sf.p.curve_of, sf.curves.n_curves)
        reachable = quant.tolerance is not None and unrounded.meets(sf.targets)
        if chosen == quant.rank or not reachable or (
                found.meets(sf.targets) and (bound is None or _over(found, unrounded, bound) is None)):
            break
    return replace(quant, rank=chosen), approx, len(parts.topology) + len(parts.coefficients)


def stored_rank(coefficients: bytes) -> int:
    """The knots' rank of an encoded coefficients part as a Quantisation's ``rank``: -r where they are on the
    leading r of a windowed fit's shared weights."""
    header = container.read_header(coefficients)
    rank = int(header["knot_rank"])
    return -rank if header.get(SHARED_KEY) else rank


def _rounding(sf: SpaceFit, fitted: TimeStage, options: FitOptions, poses: Poses, exact: np.ndarray,
              tol: FitTolerances, trials: list[dict] | None) -> Quantisation:
    """:func:`search_rounding` of a fit held in memory: each rounding measured on its stored clip (evaluated
    at every frame), the knots on the number of shared tracks that the first rounding's smallest encoding
    has."""
    p, F = sf.p, poses.n_frames
    unrounded = Errors.of(exact[:F], p.curve_of, sf.curves.n_curves)
    quant = first_quantisation(sf.targets, unrounded.rms**2, tol)
    if not tol.knot_basis:
        quant.rank = 0
    elif quant.tolerance is not None and unrounded.meets(sf.targets):
        first = encode(p, sf.curves, sf.space, fitted, options, poses, None, quant, TRIAL_LEVEL)
        quant = replace(quant, rank=stored_rank(first.coefficients))

    def measure(q: Quantisation) -> Errors:
        clip = stored_clip(p, sf.curves, sf.space, fitted, options, poses, q)
        d = stored_distances(p, clip.evaluate(clip.frame_t()), F)
        return Errors.of(d, p.curve_of, sf.curves.n_curves)

    return search_rounding(sf.targets, unrounded, quant, tol, measure, trials)


@dataclass
class Errors:
    """What the rate control reads of a clip's distances to the data: their RMS and mean square, the largest,
    and the largest on each curve (C,)."""

    rms: float
    largest: float
    curve_max: np.ndarray

    @classmethod
    def of(cls, d: np.ndarray, curve_of: np.ndarray, n_curves: int) -> Errors:
        """The errors of distances d (F, V) of vertices on curves ``curve_of`` (V,)."""
        curve_max = np.zeros(n_curves)
        np.maximum.at(curve_max, curve_of, d.max(axis=0, initial=0.0))
        return cls(float(np.sqrt(np.mean(d * d))) if d.size else 0.0, float(d.max(initial=0.0)), curve_max)

    def meets(self, targets: Targets) -> bool:
        """Whether they meet the targets."""
        return targets.meets(self.rms, self.largest)


def search_rounding(targets: Targets, unrounded: Errors, quant: Quantisation, tol: FitTolerances,
                    measure: Callable[[Quantisation], Errors], trials: list[dict] | None = None
                    ) -> Quantisation:
    """The coarsest rounding found, starting from ``quant``, whose stored clip (``measure(rounding)``) meets
    the targets, with its RMS error in [tol.quant_fill, 1] of an RMS target where the trials reach it, and no
    curve past the max bound that the unrounded fit kept within it (such curves get finer steps, the budget
    kept). Each trial is appended to ``trials``."""
    if quant.tolerance is None or not unrounded.meets(targets):
        return quant  # nothing to round for, or a target the fit itself misses
    bound = max_bound(targets, tol)
    good, bad = None, None  # the coarsest budget that met the targets; the finest one that missed the RMS
    for _ in range(tol.quant_retries + 1):
        found = measure(quant)
        if trials is not None:
            trials.append(_trial(targets, quant, found))
        rms_missed = targets.misses(found.rms, found.largest)[0]
        over = None if bound is None or rms_missed else _over(found, unrounded, bound)
        if over is not None:  # finer steps on the curves past the bound, the budget kept
            quant = quant.refined(over, len(found.curve_max))
            continue
        if found.meets(targets):
            good = quant
            if quant.knot_rms is None or found.rms >= tol.quant_fill * targets.rms:
                return good
        else:
            bad = quant
        if quant.knot_rms is None:
            quant = quant.finer()
            continue
        factor = growth(found.rms**2, unrounded.rms**2, targets.rms, tol)
        if good is None:  # the first budget missed: shrink towards the aim
            quant = quant.coarser(factor)
            continue
        if bad is not None:
            gap = bad.knot_rms / good.knot_rms  # bisect (in log) between the last met and the first missed
            if gap < tol.bisect_until:
                return good
            factor = float(np.sqrt(gap))
        quant = replace(good.coarser(factor), refine=quant.refine)  # the refinements found so far stay
    return good or quant


def _over(found: Errors, unrounded: Errors, bound: float) -> np.ndarray | None:
    """Indices of the curves on which a vertex of the stored clip is past the max bound while the unrounded
    fit kept it within (the rounding's doing), or None."""
    over = np.flatnonzero((found.curve_max > bound) & (unrounded.curve_max <= bound))
    return over if len(over) else None


def _trial(targets: Targets, quant: Quantisation, found: Errors) -> dict:
    """One rate-control trial for the report: the knots' RMS budget, how many curves have refined steps, and
    the stored clip's RMS and max error over the targets (an RMS target's when there is no max target)."""
    return {"knot_rms": quant.knot_rms, "knot_rank": quant.rank,
            "refined_curves": 0 if quant.refine is None else int(np.any(quant.refine > 0, axis=1).sum()),
            "rms_over_target": found.rms / targets.rms if targets.rms else None,
            "max_over_target": found.largest / (targets.max or targets.rms or 1.0)}


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
