"""Rate control: how coarsely the fitted clip is rounded. The rounding halves while it alone makes a target
missed that the unrounded fit met, and the knots' budget grows while the stored clip stays well inside an RMS
target; every trial is encoded and measured (docs/compression.md)."""

from __future__ import annotations

import numpy as np

from ..model.adaptive import Targets
from ..model.clipformat import TRIAL_LEVEL
from ..model.fitcore import TimeStage
from ..model.quantise import power_of_two_step
from ..poses import Poses
from .encode import Quantisation, decode, encode
from .options import FitOptions, FitTolerances
from .problem import meets, stored_distances
from .spacestage import SpaceFit


def first_quantisation(targets: Targets, exact: np.ndarray, tol: FitTolerances) -> Quantisation:
    """The first rounding tried: a share of the tightest target per coordinate; with an RMS target, the knots
    get most of what the unrounded fit leaves of it, moving no vertex by more than tol.knot_cap times that
    budget nor by more than what it leaves of a max target."""
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
    limit = np.inf
    if targets.max is not None:  # what the fit leaves of the max target, shared by the rest and the knots
        limit = max(tolerance, (targets.max - float(exact.max(initial=0.0))) / (2 * np.sqrt(3)))
    return Quantisation(tolerance, knot_rms, min(tol.knot_cap * knot_rms, limit), limit)


def quantised(sf: SpaceFit, fitted: TimeStage, options: FitOptions, poses: Poses, exact: np.ndarray,
              tol: FitTolerances) -> tuple[Quantisation, np.ndarray, int]:
    """(rounding, decoded positions (F, V, 3), stored bytes) of the clip of a fit: the rounding halves while
    it alone makes a target missed that the unrounded fit met, and the knots' budget grows while the stored
    clip stays well inside an RMS target (the estimate of the noise is conservative)."""
    p, F = sf.p, poses.n_frames
    quant = first_quantisation(sf.targets, exact[:F], tol)
    best, missed = None, None  # the coarsest rounding that met the targets; the finest grown one that did not
    soft = None  # the soft max bound, once the first rounding has kept within it (growth may not pass it)
    for _ in range(tol.quant_retries + 1):
        parts = encode(p, sf.curves, sf.space, fitted, options, poses, None, quant, TRIAL_LEVEL)
        clip = decode(parts)
        approx = clip.evaluate(clip.frame_t())
        found = (quant, approx, len(parts.topology) + len(parts.coefficients))
        if quant.tolerance is None or not meets(sf.targets, exact[:F]):
            return found
        d = stored_distances(p, approx, F)
        if best is None and meets(sf.targets, d):
            bound = soft_max(sf.targets, tol)
            soft = bound if bound is not None and d.max(initial=0.0) <= bound else None
        if not meets(sf.targets, d) or (soft is not None and d.max(initial=0.0) > soft):
            if best is None:
                quant = quant.finer()
                continue
            missed = quant
        else:
            best = found
            if quant.knot_rms is None or np.sqrt(np.mean(d * d)) > tol.quant_fill * sf.targets.rms:
                return best
        good = best[0]
        if missed is None:
            quant = good.coarser(growth(float(np.mean(d * d)), float(np.mean(exact[:F] ** 2)),
                                        sf.targets.rms, tol))
            continue
        gap = missed.knot_rms / good.knot_rms  # a grown rounding missed: halve the gap (in log) between them
        if gap < tol.bisect_until:
            return best
        quant = good.coarser(float(np.sqrt(gap)))
    return best or found


def soft_max(targets: Targets, tol: FitTolerances) -> float | None:
    """The soft max bound of an RMS target without a max target (tol.soft_max_ratio), else None."""
    if tol.soft_max_ratio is None or targets.rms is None or targets.max is not None:
        return None
    return tol.soft_max_ratio * targets.rms


def growth(stored: float, exact: float, target: float, tol: FitTolerances) -> float:
    """Factor on the knots' budget that should bring the stored mean square error ``stored`` to tol.quant_aim
    of the RMS ``target``, the rounding adding ``stored - exact`` (proportional to the budget squared)."""
    added = stored - exact
    if added <= 0:
        return tol.growth_max
    aim = max((tol.quant_aim * target) ** 2 - exact, 0.0)
    return float(np.clip(np.sqrt(aim / added), tol.growth_min, tol.growth_max))
