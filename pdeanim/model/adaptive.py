"""Error-driven choice of the number and placement of time segments.

Start from one segment; while the target (RMS and/or max distance, absolute) is not met, split the
segments holding the worst frames at their worst interior frame, refit the time stage (the space stage is
fitted once), and stop when the target is met, no segment can be split (2-frame segments), or the segment
budget is spent. Where the spatial floor alone exceeds the target, the search aims just above the floor
instead (more segments cannot help) and says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .fitcore import SpaceStage, TimeStage, time_stage
from .segments import Segmentation
from .targets import Targets


@dataclass
class AdaptiveResult:
    """The chosen time stage and what the search did."""

    time: TimeStage
    met: bool
    floor_exceeds_target: bool
    history: list[dict] = field(default_factory=list)
    cap_reached: bool = False  # the search stopped at max_segments with the (floor-raised) target not met
    unsplittable: bool = False  # the search stopped because every segment is a single frame interval


def _frame_badness(d: np.ndarray, targets: Targets) -> tuple[np.ndarray, bool]:
    """(F,) how far each frame is over target (ratio), and whether all targets are met."""
    badness = targets.excess(np.sqrt(np.mean(d * d, axis=1)), d.max(axis=1))
    return np.asarray(badness), targets.met_by(d)


def _splits(segm: Segmentation, badness: np.ndarray, n_split: int) -> Segmentation:
    """Split up to n_split segments with the largest error energy, each near its error-weighted centre.

    The split frame is the error-weighted mean frame, kept inside the middle half of the segment so that
    long segments are bisected rather than nibbled at their ends.
    """
    seg = segm.frame_segment()
    energy = np.bincount(seg, badness**2, minlength=segm.n_segments)
    splittable = np.diff(segm.bounds) >= 2
    score = np.where(splittable, energy, -np.inf)
    chosen = [
        s for s in np.argsort(-score, kind="stable")[:n_split] if np.isfinite(score[s]) and score[s] > 0
    ]
    new_bounds = list(segm.bounds)
    for s in chosen:
        lo, hi = int(segm.bounds[s]), int(segm.bounds[s + 1])
        frames = np.arange(lo, hi + 1)
        w = badness[frames] ** 2
        centre = float((frames * w).sum() / w.sum()) if w.sum() > 0 else 0.5 * (lo + hi)
        quarter = (hi - lo) / 4.0
        new_bounds.append(int(np.clip(round(centre), max(lo + 1, np.ceil(lo + quarter)),
                                      min(hi - 1, np.floor(hi - quarter)))))
    return Segmentation(np.unique(np.array(new_bounds, dtype=np.int64)), segm.t)


def fit_adaptive(space: SpaceStage, segm: Segmentation, targets: Targets,
                 distances: Callable[[TimeStage], np.ndarray], floor_d: np.ndarray,
                 max_segments: int, loop: bool = False,
                 progress: Callable[[float, str], None] | None = None,
                 keep: np.ndarray | None = None) -> AdaptiveResult:
    """Refine segmentation until targets are met; ``distances(time)`` gives (F, V) model-to-data distances.
    ``keep``: frames whose boundaries (in the starting ``segm``) are never merged away."""
    floor_targets, floor_high = _effective_targets(targets, floor_d)
    history: list[dict] = []
    cap_reached = unsplittable = False
    while True:
        time = time_stage(space, segm, loop, refine_iters=SEARCH_REFINE)
        d = distances(time)
        badness, met = _frame_badness(d, floor_targets)
        history.append({"segments": segm.n_segments, "rms": float(np.sqrt(np.mean(d * d))),
                        "max": float(d.max())})
        if progress:
            progress(min(segm.n_segments / max(max_segments, 1), 1.0),
                     f"segments {segm.n_segments}: {_progress_errors(d, floor_targets)}")
        if met:
            break
        if segm.n_segments >= max_segments:
            cap_reached = True
            break
        n_split = max(1, min(_split_count(segm.n_segments, history[-1]["rms"], history[-1]["max"],
                                          floor_targets), max_segments - segm.n_segments))
        new = _splits(segm, badness, n_split)
        if new.n_segments == segm.n_segments:
            unsplittable = True
            break
        segm = new
    if met and not floor_high and segm.n_segments <= MERGE_MAX_SEGMENTS:
        time, d = _merge(space, time, d, floor_targets, distances, loop, history, keep)
    time, d = _polish(space, time, d, distances, loop, floor_targets)
    _, met_real = _frame_badness(d, targets)
    return AdaptiveResult(time, met_real, floor_high, history, cap_reached and not met_real,
                          unsplittable and not met_real)


GROWTH_MIN, GROWTH_MAX = 4.0 / 3.0, 2.0
"""Bounds of the factor by which a search round multiplies the number of segments."""


def _split_count(n_segments: int, rms: float, largest: float, targets: Targets) -> int:
    """Segments to split in the next round, given the round's RMS and largest distance: the count grows by
    sqrt(error / target) (the error of a piecewise-linear track falls with the square of the number of
    segments), between GROWTH_MIN and GROWTH_MAX: far from the target the search doubles, so long clips need a
    few rounds, not dozens."""
    ratio = max(1.0, targets.excess(rms, largest))
    growth = float(np.clip(np.sqrt(ratio), GROWTH_MIN, GROWTH_MAX))
    return int(np.floor(n_segments * (growth - 1.0) + 1e-9))


def _progress_errors(d: np.ndarray, targets: Targets) -> str:
    """"rms X (target Y), max ..." for a progress line."""
    parts = []
    if targets.rms is not None:
        parts.append(f"rms {np.sqrt(np.mean(d * d)):.3g} (target {targets.rms:.3g})")
    if targets.max is not None:
        parts.append(f"max {d.max():.3g} (target {targets.max:.3g})")
    return ", ".join(parts)


MAX_MERGE_TRIES = 3
MERGE_MAX_SEGMENTS = 16
"""Boundaries are removed only from searches that ended with at most this many segments: each try is a whole
time fit, and removing one of many segments saves little (on a 401-frame clip ending at 256 segments the
three tries took 15 of 105 s and could remove at most 3 of 257 knots per track)."""
SEARCH_REFINE = 3
"""Golden steps for the time constants while searching segmentations (the chosen one gets the full count)."""


def _polish(space: SpaceStage, time: TimeStage, d: np.ndarray, distances: Callable[[TimeStage], np.ndarray],
            loop: bool, targets: Targets) -> tuple[TimeStage, np.ndarray]:
    """Refit the chosen segmentation with the full refinement; keep it only if it is better and still meets
    every target the search met."""
    fine = time_stage(space, time.segm, loop)
    df = distances(fine)
    met_before, met_after = _frame_badness(d, targets)[1], _frame_badness(df, targets)[1]
    better = np.sum(df * df) <= np.sum(d * d) and (met_after or not met_before)
    return (fine, df) if better else (time, d)


def _merge(space: SpaceStage, time: TimeStage, d: np.ndarray, targets: Targets,
           distances: Callable[[TimeStage], np.ndarray], loop: bool, history: list[dict],
           keep: np.ndarray | None = None) -> tuple[TimeStage, np.ndarray]:
    """Greedily remove segment boundaries (quietest neighbours first, none at a frame of ``keep``) while the
    targets stay met."""
    tries = 0
    while time.segm.n_segments > 1 and tries < MAX_MERGE_TRIES:
        segm = time.segm
        badness, _ = _frame_badness(d, targets)
        energy = np.bincount(segm.frame_segment(), badness**2, minlength=segm.n_segments)
        order = np.argsort(energy[:-1] + energy[1:], kind="stable")
        if keep is not None:
            order = order[~np.isin(segm.bounds[order + 1], keep)]
        merged = False
        for s in order[: MAX_MERGE_TRIES - tries]:
            tries += 1
            cand = time_stage(space, segm.merge(int(s)), loop, refine_iters=SEARCH_REFINE)
            dc = distances(cand)
            if _frame_badness(dc, targets)[1]:
                time, d, merged = cand, dc, True
                history.append({"segments": cand.segm.n_segments, "rms": float(np.sqrt(np.mean(dc * dc))),
                                "max": float(dc.max()), "merged": True})
                break
        if not merged:
            break
    return time, d


def _effective_targets(targets: Targets, floor_d: np.ndarray) -> tuple[Targets, bool]:
    """Targets raised to just above the spatial floor where the floor alone exceeds them."""
    floor_rms = float(np.sqrt(np.mean(floor_d * floor_d)))
    floor_max = float(floor_d.max()) if floor_d.size else 0.0
    rms_missed, max_missed = targets.misses(floor_rms, floor_max)
    rms = floor_rms * 1.05 if rms_missed else targets.rms
    mx = floor_max * 1.05 if max_missed else targets.max
    return Targets(rms, mx), rms_missed or max_missed
