"""Fits with a bone layer (format 1.1, docs/format.md §3.9): bones move many vertices with few numbers and the
dynamic-PDE curves fit what the decoded bones leave.

1. The bones: a skinned glTF's own skeleton (:mod:`pdeanim.bones.gltfskin`) or a skinning decomposition of
   the welded trajectories (:mod:`pdeanim.bones.motion`).
2. The joint rate control (:class:`BoneBudgets`): the bone layer is fitted in time and rounded
   (:func:`pdeanim.model.bonelayer.encode_bones`) at RMS budgets searched by its error measured exactly as a
   reader skins it against the frames: the coarsest budget whose bones alone meet the targets (RMS within
   BONES_ALONE_FILL, every vertex within the max bound) gives a clip with a zero residual, and the coarsest
   within each share of RESIDUAL_AIMS a clip with residual curves.
3. The residual poses, frames - skinned + rest, are fitted by the ordinary pipeline about the stored rest pose
   (motion "displacement"): its own rate control sees the whole clip's error, spends what the bones leave of
   the budget and refines the curves where a vertex is past the max bound. The bone layer is appended to the
   coefficients part.
4. The stored clip (bones and curves) is decoded and measured at every source frame: the report's errors.
   The smallest clip that meets the targets is kept.

With ``bones="auto"`` the bone counts of BONE_LADDER are tried upwards from FIRST_BONES while the clip gets
smaller, against the clip without bones (kept where it is smaller, e.g. on cloth-like motion)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from .. import container
from ..bones.gltfskin import SkinBones
from ..bones.motion import fitted_bones
from ..bones.trajweld import weld_trajectories
from ..clipparts import ClipParts
from ..curveset import CurveSet
from ..errors import ParameterError
from ..model import quantise
from ..model.adaptive import Targets
from ..model.bonelayer import (
    BoneMotion,
    add_bone_layer,
    bones_header_arrays,
    encode_bones,
    skin,
    skinned_positions,
)
from ..model.clipformat import TRIAL_LEVEL
from ..model.clipmodel import clip_from_parts
from ..model.metrics import bbox_diagonal, error_summary
from ..poses import Poses
from ..progress import Progress, sub_progress
from .options import FitOptions, FitTolerances
from .ratecontrol import first_quantisation, max_bound

BONE_LADDER = (8, 16, 32, 64, 128)
FIRST_BONES = 8
"""``bones="auto"``: the first count tried; larger ones follow while each makes the clip smaller."""
MIN_POINTS_PER_BONE = 24
"""Counts above (distinct trajectories / this) are not tried: bones of a few vertices cost more than they
move."""
BONE_SHARE = 0.5
"""The budget search starts at this share of the RMS goal (the bone layer's encoder bound; the decoded layer
lands well inside it)."""
AUTO_SKIN_SHARE = 0.7
"""``bones="auto"``: decompositions stop once the skinning alone is within this share of the RMS target ..."""
AUTO_GAIN = 0.1
"""... or once doubling the bones cut its RMS error by less than this share (motion that bones do not
explain: a morph, cloth). A count is fitted only where its skinning is within the target: more is left to
the residual curves than a clip without bones spends (horse-collapse at 3e-3: 32 bones skin to 0.94 of the
target and the clip is 155 KB, 64 bones to 0.61 and 143 KB, no bones 147 KB)."""
SPARSE_SHARE = 0.5
"""The decomposition keeps a vertex's fewest influences whose RMS distance over frames is within this share
of the RMS goal (in quadrature) of its best with four: zero weights and repeated bone indices compress to
almost nothing (see docs/compression.md, "Sparser skinning weights")."""
MAX_SHARE_OF_MAX = 1 / 3
BONES_ALONE_FILL = 0.95
"""The bone layer alone (a zero residual) is tried at its coarsest encoding within this share of the RMS
goal ..."""
BONES_ALONE_MAX = 0.97
"""... and this share of the max bound (a max target, or the soft bound of an RMS target)."""
RESIDUAL_AIMS = (0.65,)
"""With residual curves: the bone layer at its coarsest encoding within each of these shares of the RMS goal,
coarser while the clip gets smaller (the curves fit what the bones leave). One share: on horse-collapse at
3e-3 (128 bones) 0.5, 0.65, 0.8 and 0.95 gave 125.1, 120.8, 122.5 and 134.4 KB, and each share costs a
residual fit."""
BUDGET_GROWTH = 1.5
BUDGET_STEPS = 6
BUDGET_BISECTIONS = 1
"""With a max target only, the bone layer's RMS budget is this share of it."""
SLOPE_STEPS = 4
"""A skinned glTF's bone layer alone: finer budgets tried past the coarsest within the bounds
(:meth:`BoneBudgets.by_slope`)."""

FitFn = Callable[..., ClipParts]


def fit_with_bones(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
                   curves: CurveSet | None, skin: SkinBones | None, fit: FitFn) -> ClipParts:
    """The clip of ``poses`` with the bone layer that ``options.bones`` and ``skin`` ask for (``fit``: the
    pipeline's fit without bones)."""
    start = time.perf_counter()
    plain = replace(options, bones=0)
    too_big = poses.n_frames * poses.n_vertices > tol.window_fit_values
    if too_big and options.bones != "auto":
        raise ParameterError(f"a bone layer is fitted with every frame in memory: at most "
                             f"{tol.window_fit_values:,} frame-vertex values, this input has "
                             f"{poses.n_frames * poses.n_vertices:,} (fit it without bones, or fewer frames)")
    if too_big:
        parts = fit(poses, plain, progress, curves=curves, tolerances=tol)
        parts.report["bones"] = {"n_bones": 0, "source": "none", "skipped": "input larger than a bone fit "
                                 "holds in memory (FitTolerances.window_fit_values)"}
    elif skin is not None:
        skin_tol = tol
        if tol.soft_max_ratio is not None and tol.skin_max_ratio is not None:
            skin_tol = replace(tol, soft_max_ratio=min(tol.soft_max_ratio, tol.skin_max_ratio))
        parts = _bone_clip(poses, plain, progress, skin_tol, curves, skin.motion, skin.rest, fit,
                           slope=tol.skin_rd_slope)
        parts.report["bones"].update(source="gltf skin", joints=skin.n_joints)
    elif options.bones != "auto":
        parts = _decomposed(poses, plain, int(options.bones), progress, tol, curves, fit)
    else:
        parts = _auto(poses, plain, progress, tol, curves, fit)
    parts.report["bones"]["seconds_total"] = time.perf_counter() - start
    return parts


def _auto(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
          curves: CurveSet | None, fit: FitFn) -> ClipParts:
    """The smallest clip among no bones and the ladder's counts. Decompositions (cheap next to a fit) go up
    the ladder until the skinning alone is within AUTO_SKIN_SHARE of the RMS target or stops improving by
    AUTO_GAIN. The first count within that share (else the last one within the target) and the next ones up
    are fitted while each clip is smaller than the best so far."""
    best = fit(poses, options, sub_progress(progress, 0.0, 0.3), curves=curves, tolerances=tol)
    best.report["bones"] = {"n_bones": 0, "source": "none"}
    tried = [{"bones": 0, "bytes": _size(best), "rel_rms": best.report.get("rel_rms")}]
    n_points = weld_trajectories(poses.vertices).n_points if poses.n_frames > 1 else 0
    ladder = [b for b in BONE_LADDER if b >= FIRST_BONES and b * MIN_POINTS_PER_BONE <= n_points]
    diag = bbox_diagonal(np.asarray(poses.vertices[0], np.float64))
    targets = options.targets(diag)
    if options.motion != "displacement" or options.segments is not None or targets.rms is None:
        ladder = []  # a bone layer needs a displacement fit with an RMS target (auto)
    skinning, found, previous = [], {}, np.inf
    for i, B in enumerate(ladder):
        progress(0.3 + 0.3 * i / len(ladder), f"skinning decomposition, {B} bones")
        t0 = time.perf_counter()
        found[B] = (*fitted_bones(poses.vertices, B, sparse_rms=SPARSE_SHARE * targets.rms),
                    time.perf_counter() - t0)
        rms = found[B][1]
        skinning.append({"bones": B, "skinning_rel_rms": rms / diag if diag else None,
                         "seconds": found[B][2]})
        if rms <= AUTO_SKIN_SHARE * targets.rms or rms > (1 - AUTO_GAIN) * previous:
            break
        previous = rms
    close = [B for B in found if found[B][1] <= AUTO_SKIN_SHARE * targets.rms]
    start = close[:1] or [B for B in found if found[B][1] <= targets.rms][-1:]
    fits = [b for b in ladder if start and b >= start[0]]
    for i, B in enumerate(fits):
        step = sub_progress(progress, 0.6 + 0.4 * i / len(fits), 0.6 + 0.4 * (i + 1) / len(fits))
        parts = _decomposed(poses, options, B, step, tol, curves, fit, found.get(B))
        met = parts.report.get("target_met")
        tried.append({"bones": B, "bytes": _size(parts), "rel_rms": parts.report.get("rel_rms"), "met": met})
        if _size(parts) >= _size(best) or (best.report.get("target_met") and not met):
            break
        best = parts
    best.report["bones"].update(candidates=tried, skinning=skinning)
    return best


def _decomposed(poses: Poses, options: FitOptions, bones: int, progress: Progress, tol: FitTolerances,
                curves: CurveSet | None, fit: FitFn,
                found: tuple[BoneMotion, float, float] | None = None) -> ClipParts:
    """The clip with at most ``bones`` bones found by a skinning decomposition of the poses (``found``: that
    decomposition's (motion, RMS, seconds) when already made)."""
    if found is None:
        progress(0.0, f"skinning decomposition, {bones} bones")
        t0 = time.perf_counter()
        goal = bone_goal(options.targets(bbox_diagonal(np.asarray(poses.vertices[0], np.float64))))
        found = (*fitted_bones(poses.vertices, bones, sparse_rms=SPARSE_SHARE * goal),
                 time.perf_counter() - t0)
    motion, skin_rms, seconds = found
    parts = _bone_clip(poses, options, sub_progress(progress, 0.2, 1.0), tol, curves, motion,
                       np.asarray(poses.vertices[0], np.float64), fit)
    diag = parts.report["bones"]["diagonal"]
    parts.report["bones"].update(source="decomposition", requested=bones, decomposition_seconds=seconds,
                                 skinning_rel_rms=skin_rms / diag if diag else None)
    return parts


def _bone_clip(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
               curves: CurveSet | None, motion: BoneMotion, rest: np.ndarray, fit: FitFn,
               slope: float | None = None) -> ClipParts:
    """The smallest clip of one bone motion about ``rest`` (V, 3) that meets the targets, of (steps 2-5 of
    the module docstring): the bone layer alone under a zero residual, where its coarsest encoding that
    meets the targets exists, and the bone layer coarsened to each share of RESIDUAL_AIMS with the residual
    curves fitted on top. With a rate-distortion ``slope`` (a skinned glTF on its own skeleton), the bone
    layer alone is the finer encoding :meth:`BoneBudgets.by_slope` prefers, and of the clips that meet the
    targets the one of least bytes x max error^(1 / slope) is kept instead of the smallest."""
    X = poses.vertices
    diag = bbox_diagonal(np.asarray(X[0], np.float64))
    targets = options.targets(diag)
    bound = max_bound(targets, tol)
    rest_q = stored_rest(rest, first_quantisation(targets, 0.0, tol).tolerance, diag)
    goal = bone_goal(targets)
    search = BoneBudgets(motion, rest_q, X, _normalised(poses.times), options.loop, goal)
    candidates: list[ClipParts] = []
    alone = None
    if search.floor_meets(BONES_ALONE_FILL, BONES_ALONE_MAX * bound if bound is not None else None):
        largest = BONES_ALONE_MAX * bound if bound is not None else None
        alone = search.coarsest(BONES_ALONE_FILL, largest)
        if alone is not None and slope is not None:
            alone = search.by_slope(alone, slope, BONES_ALONE_FILL, largest)
    if alone is not None:
        candidates.append(_residual_clip(poses, options, sub_progress(progress, 0.0, 0.2), tol, curves,
                                         search, alone, rest_q, fit, zero=True))
    budgets: list[float] = []
    for i, aim in enumerate(RESIDUAL_AIMS):
        step = sub_progress(progress, 0.2 + 0.8 * i / len(RESIDUAL_AIMS),
                            0.2 + 0.8 * (i + 1) / len(RESIDUAL_AIMS))
        b = search.coarsest(aim, None) or search.first
        if b in budgets:
            continue
        budgets.append(b)
        parts = _residual_clip(poses, options, step, tol, curves, search, b, rest_q, fit, zero=False)
        candidates.append(parts)
        if len(candidates) > 1 and _size(parts) >= min(_size(c) for c in candidates[:-1]):
            break  # a coarser bone layer made the clip larger: the residual pays for it
    met = [c for c in candidates if c.report.get("target_met")]
    if slope is None:
        best = min(met or candidates, key=_size)
    else:
        best = min(met or candidates, key=lambda c: rd_cost(_size(c), c.report.get("max", 0.0), slope))
    best.report["bones"]["tried"] = [{"residual": not c.report["bones"]["zero_residual"],
                                      "budget_rms": c.report["bones"]["budget_rms"], "bytes": _size(c),
                                      "rel_rms": c.report.get("rel_rms"), "rel_max": c.report.get("rel_max"),
                                      "met": c.report.get("target_met")} for c in candidates]
    best.report["bones"]["budget_search"] = search.trials()
    return best


def _residual_clip(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
                   curves: CurveSet | None, search: BoneBudgets, budget: float, rest_q: np.ndarray,
                   fit: FitFn, zero: bool) -> ClipParts:
    """The clip of the bone layer encoded at ``budget`` and the residual curves (steps 2-5; ``zero``: the
    residual is the rest pose at every frame, curves whose knots are all 0, when the bones alone meet the
    targets)."""
    X = poses.vertices
    diag = bbox_diagonal(np.asarray(X[0], np.float64))
    targets = options.targets(diag)
    enc, base = search.encoded(budget)
    moved = np.broadcast_to(rest_q.astype(np.float32), X.shape) if zero else (X - base)
    residual = Poses(np.array(moved + (0 if zero else rest_q.astype(np.float32)), np.float32), poses.faces,
                     poses.times, dict(poses.meta), rest=rest_q)
    absolute = replace(options, target_rms=targets.rms, target_rel_rms=None, target_max=targets.max,
                       target_rel_max=None)
    parts = fit(residual, absolute, progress, curves=curves, tolerances=tol)
    residual_bytes = _size(parts)
    parts.coefficients = append_bone_layer(parts.coefficients, enc)
    report = _measured(parts, poses, diag, targets)
    report["options"] = {**report.get("options", {}), **{k: v for k, v in options.to_dict().items()
                                                          if k.startswith("target")}}
    report["bones"] = {"n_bones": enc.n_bones, "influences": enc.n_influences, "segments": enc.n_segments,
                       "bone_bytes": _size(parts) - residual_bytes, "residual_bytes": residual_bytes,
                       "residual_share": residual_bytes / _size(parts), "budget_rms": budget,
                       "zero_residual": zero, "encoding": enc.report, "diagonal": diag}
    parts.report = report
    return parts


class BoneBudgets:
    """Encodings of one bone motion at RMS budgets (absolute), each measured exactly as a reader skins it on
    the stored rest pose against the source frames: the budget search of the joint rate control (the
    encoder's own RMS bound is conservative: the decoded layer lands at 0.3-0.7 of it on horse-collapse and
    CesiumMan)."""

    def __init__(self, motion: BoneMotion, rest_q: np.ndarray, frames: np.ndarray, t: np.ndarray,
                 looping: bool, goal: float):
        self.motion, self.rest_q, self.frames, self.t, self.looping = motion, rest_q, frames, t, looping
        self.goal = goal
        self.first = BONE_SHARE * goal
        self._found: dict[float, tuple[Any, float, float]] = {}  # budget -> (encoding, RMS, max), no frames

    def encoded(self, budget: float) -> tuple[Any, np.ndarray]:
        """(encoded bone layer, (F, V, 3) float32 skinned positions at the frames) at ``budget``."""
        self._measure(budget)
        enc = self._found[budget][0]
        return enc, skinned_positions(enc, self.rest_q, self.t, self.looping)

    def _measure(self, budget: float) -> tuple[float, float]:
        """(RMS, max) vertex distance of the bone layer at ``budget`` from the frames."""
        if budget not in self._found:
            enc = encode_bones(self.motion, self.t, budget, self.rest_q, self.looping)
            base = skinned_positions(enc, self.rest_q, self.t, self.looping)
            d = np.linalg.norm(base.astype(np.float64) - self.frames, axis=-1)
            self._found[budget] = (enc, float(np.sqrt(np.mean(d * d))), float(d.max(initial=0.0)))
        _, rms, largest = self._found[budget]
        return rms, largest

    def floor_meets(self, rms_share: float, largest: float | None) -> bool:
        """Whether the unencoded skinning (exact tracks and weights) is within ``rms_share`` of the goal and
        ``largest``: no encoding of it can be closer."""
        d = np.linalg.norm(skin(self.motion, self.rest_q) - self.frames, axis=-1)
        return float(np.sqrt(np.mean(d * d))) <= rms_share * self.goal and (
            largest is None or float(d.max(initial=0.0)) <= largest)

    def coarsest(self, rms_share: float, largest: float | None) -> float | None:
        """The coarsest budget found whose bone layer is within ``rms_share`` of the goal (and ``largest``,
        when given): grown by BUDGET_GROWTH from BONE_SHARE of the goal while it stays within, then bisected
        (in log) BUDGET_BISECTIONS times; None when even the finest tried misses."""
        def ok(b: float) -> bool:
            rms, mx = self._measure(b)
            return rms <= rms_share * self.goal and (largest is None or mx <= largest)

        lo, hi = None, None
        b = self.first
        for _ in range(BUDGET_STEPS):
            if ok(b):
                lo = b
                if hi is not None:
                    break
                b *= BUDGET_GROWTH
            else:
                hi = b
                if lo is not None:
                    break
                b /= BUDGET_GROWTH
        if lo is None:
            return None
        for _ in range(BUDGET_BISECTIONS if hi is not None else 0):
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
        return lo

    def by_slope(self, budget: float, slope: float, rms_share: float, largest: float | None) -> float:
        """Of ``budget`` and up to SLOPE_STEPS finer ones (each BUDGET_GROWTH finer) within ``rms_share`` of
        the goal and ``largest``, the budget whose bone layer has the least :func:`rd_cost` (its bytes at the
        trial zstd level, its max distance): a finer layer is taken where it cuts the largest error by more,
        relatively, than the slope-th power of the bytes it adds (the coarsest encoding within the bounds can
        be 2-3x off at the worst vertex for a few percent of the bytes: one joint segment fewer, 4-bit
        weights)."""
        def cost(b: float) -> float:
            rms, mx = self._measure(b)
            if rms > rms_share * self.goal or (largest is not None and mx > largest):
                return math.inf
            return rd_cost(self._bytes(b), mx, slope)

        best, b = budget, budget
        for _ in range(SLOPE_STEPS):
            b /= BUDGET_GROWTH
            if cost(b) < cost(best):
                best = b
        return best

    def _bytes(self, budget: float) -> int:
        """Bytes of the bone layer encoded at ``budget`` (its arrays packed at the trial zstd level)."""
        enc = self._found[budget][0]
        header, arrays = bones_header_arrays(enc)
        return len(container.pack(header, arrays, {name: container.SMALLEST for name in arrays},
                                  level=TRIAL_LEVEL))

    def trials(self) -> list[dict[str, float]]:
        """Every budget measured: budget, the bone layer's RMS and max over the goal, weight bits,
        segments."""
        return [{"budget_rms": b, "rms_over_goal": v[1] / self.goal, "max_over_goal": v[2] / self.goal,
                 "weight_bits": v[0].weight_bits, "segments": v[0].n_segments}
                for b, v in sorted(self._found.items())]


def rd_cost(size: float, largest: float, slope: float) -> float:
    """The rate-distortion cost by which the bone path of a skinned glTF compares encodings and clips:
    log(bytes) + log(max error) / slope (of two, the finer is preferred where its max error is lower by
    more than its bytes are higher to the power ``slope``)."""
    return math.log(max(size, 1)) + math.log(max(largest, 1e-30)) / slope


def bone_goal(targets: Targets) -> float:
    """The RMS goal the bone layer's budgets are measured against (absolute): an RMS target, else a share of
    a max target."""
    return targets.rms if targets.rms is not None else targets.max * MAX_SHARE_OF_MAX


def stored_rest(rest: np.ndarray, tolerance: float | None, diag: float) -> np.ndarray:
    """(V, 3) float64 the rest pose as the topology part stores and a reader decodes it, rounded to the
    step the fit will use (rounding it again on that grid, or a finer one from the same corner, leaves it
    unchanged, so the bones are skinned on exactly the rest pose the clip stores)."""
    rest = np.asarray(np.asarray(rest, np.float32), np.float64)
    origin, step = quantise.rest_origin_step(rest, tolerance if tolerance is not None else 1e-6 * (diag or 1))
    q = np.rint((rest - origin) / step)
    return np.asarray(quantise.dequantise(q, step, origin), np.float32).astype(np.float64)


def append_bone_layer(coefficients: bytes, enc: Any) -> bytes:
    """The coefficients part with the bone layer's keys and arrays appended (format 1.1, ``required``), the
    residual curves' arrays kept in the encodings the fit chose (compare
    :func:`pdeanim.model.bonelayer.repack_with_bone_layer`, which packs every array at its smallest)."""
    encodings = container.array_encodings(coefficients)
    header, arrays = container.unpack(coefficients)
    arrays = dict(arrays)
    add_bone_layer(header, arrays, enc)
    encodings.update({name: container.SMALLEST for name in arrays if name.startswith("bone_")})
    return container.pack(header, arrays, encodings)


def _measured(parts: ClipParts, poses: Poses, diag: float, targets: Targets) -> dict[str, Any]:
    """The residual fit's report with the errors of the stored clip (bones and curves) at every frame."""
    clip = clip_from_parts(*container.unpack(parts.topology), *container.unpack(parts.coefficients))
    approx = clip.evaluate(clip.frame_t())[: poses.n_frames]
    X = poses.vertices
    report = dict(parts.report)
    summary = error_summary(X, approx, diag)
    d = np.linalg.norm(approx.astype(np.float64) - X, axis=-1)
    met = bool((targets.rms is None or summary["rms"] <= targets.rms)
               and (targets.max is None or summary["max"] <= targets.max))
    report.update(summary, target_met=met, per_frame_rms=np.sqrt(np.mean(d * d, axis=1)).tolist(),
                  per_frame_max=d.max(axis=1).tolist(), targets={"rms": targets.rms, "max": targets.max},
                  format_version=container.read_header(parts.coefficients)["format_version"],
                  sizes=parts.sizes(poses.n_frames, poses.n_vertices))
    return report


def _normalised(times: np.ndarray) -> np.ndarray:
    times = np.asarray(times, np.float64)
    span = times[-1] - times[0]
    return (times - times[0]) / span if span > 0 else np.zeros_like(times)


def _size(parts: ClipParts) -> int:
    return len(parts.topology) + len(parts.coefficients)
