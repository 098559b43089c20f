"""Fits with a bone layer (format 1.1, docs/format.md §3.9): bones move many vertices with few numbers and the
dynamic-PDE curves fit what the decoded bones leave.

1. The bones: a skinned glTF's own skeleton (:mod:`pdeanim.bones.gltfskin`) or a skinning decomposition of
   the welded trajectories (:mod:`pdeanim.bones.motion`).
2. The bone layer is fitted in time and rounded (:func:`pdeanim.model.bonelayer.encode_bones`, within
   BONE_SHARE of the RMS target), then evaluated exactly as a reader does at the frame times.
3. The residual poses, frames - skinned + rest, are fitted by the ordinary pipeline about the stored rest pose
   (motion "displacement"), and the bone layer is added to the coefficients part.
4. The stored clip (bones and curves) is decoded and measured at every source frame: the report's errors.

With ``bones="auto"`` the bone counts of BONE_LADDER are tried upwards from FIRST_BONES while the clip gets
smaller, against the clip without bones (kept where it is smaller, e.g. on cloth-like motion)."""

from __future__ import annotations

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
from ..model.bonelayer import BoneMotion, add_bone_layer, encode_bones, skinned_positions
from ..model.clipmodel import clip_from_parts
from ..model.metrics import bbox_diagonal, error_summary
from ..poses import Poses
from ..progress import Progress, sub_progress
from .options import FitOptions, FitTolerances
from .ratecontrol import first_quantisation

BONE_LADDER = (8, 16, 32, 64, 128)
FIRST_BONES = 8
"""``bones="auto"``: the first count tried; larger ones follow while each makes the clip smaller."""
MIN_POINTS_PER_BONE = 24
"""Counts above (distinct trajectories / this) are not tried: bones of a few vertices cost more than they
move."""
BONE_SHARE = 0.5
"""The bone layer's time fit and rounding may move vertices by this share of the RMS target (the residual
curves correct it): coarser bones cost fewer bytes but leave more to the curves."""
AUTO_SKIN_SHARE = 0.7
"""``bones="auto"``: decompositions stop once the skinning alone is within this share of the RMS target ..."""
AUTO_GAIN = 0.1
"""... or once doubling the bones cut its RMS error by less than this share (motion that bones do not
explain: a morph, cloth). A count is fitted only where its skinning is within the target: more is left to
the residual curves than a clip without bones spends (horse-collapse at 3e-3: 32 bones skin to 0.94 of the
target and the clip is 155 KB, 64 bones to 0.61 and 143 KB, no bones 147 KB)."""
MAX_SHARE_OF_MAX = 1 / 3
"""With a max target only, the bone layer's RMS budget is this share of it."""

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
        parts = _bone_clip(poses, plain, progress, tol, curves, skin.motion, skin.rest, fit)
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
        found[B] = (*fitted_bones(poses.vertices, B), time.perf_counter() - t0)
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
        found = (*fitted_bones(poses.vertices, bones), time.perf_counter() - t0)
    motion, skin_rms, seconds = found
    parts = _bone_clip(poses, options, sub_progress(progress, 0.2, 1.0), tol, curves, motion,
                       np.asarray(poses.vertices[0], np.float64), fit)
    diag = parts.report["bones"]["diagonal"]
    parts.report["bones"].update(source="decomposition", requested=bones, decomposition_seconds=seconds,
                                 skinning_rel_rms=skin_rms / diag if diag else None)
    return parts


def _bone_clip(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
               curves: CurveSet | None, motion: BoneMotion, rest: np.ndarray, fit: FitFn) -> ClipParts:
    """Steps 2-4 of the module docstring for one bone motion about ``rest`` (V, 3)."""
    X = poses.vertices
    diag = bbox_diagonal(np.asarray(X[0], np.float64))
    targets = options.targets(diag)
    budget = bone_budget(targets)
    rest_q = stored_rest(rest, first_quantisation(targets, 0.0, tol).tolerance, diag)
    t = _normalised(poses.times)
    enc = encode_bones(motion, t, budget, rest_q, options.loop)
    base = skinned_positions(enc, rest_q, t, options.loop)
    residual = Poses((X - base) + rest_q.astype(np.float32), poses.faces, poses.times, dict(poses.meta),
                     rest=rest_q)
    absolute = replace(options, target_rms=targets.rms, target_rel_rms=None, target_max=targets.max,
                       target_rel_max=None)
    parts = fit(residual, absolute, progress, curves=curves, tolerances=tol)
    residual_bytes = _size(parts)
    parts.coefficients = with_bone_layer(parts.coefficients, enc)
    report = _measured(parts, poses, diag, targets)
    report["options"] = {**report.get("options", {}), **{k: v for k, v in options.to_dict().items()
                                                          if k.startswith("target")}}
    report["bones"] = {"n_bones": enc.n_bones, "influences": enc.n_influences, "segments": enc.n_segments,
                       "bone_bytes": _size(parts) - residual_bytes, "residual_bytes": residual_bytes,
                       "residual_share": residual_bytes / _size(parts), "budget_rms": budget,
                       "encoding": enc.report, "diagonal": diag}
    parts.report = report
    return parts


def bone_budget(targets: Targets) -> float:
    """The bone layer's RMS budget (absolute): BONE_SHARE of an RMS target, else of a share of a max
    target."""
    goal = targets.rms if targets.rms is not None else targets.max * MAX_SHARE_OF_MAX
    return BONE_SHARE * goal


def stored_rest(rest: np.ndarray, tolerance: float | None, diag: float) -> np.ndarray:
    """(V, 3) float64 the rest pose as the topology part stores and a reader decodes it, rounded to the
    step the fit will use (rounding it again on that grid, or a finer one from the same corner, leaves it
    unchanged, so the bones are skinned on exactly the rest pose the clip stores)."""
    rest = np.asarray(np.asarray(rest, np.float32), np.float64)
    origin, step = quantise.rest_origin_step(rest, tolerance if tolerance is not None else 1e-6 * (diag or 1))
    q = np.rint((rest - origin) / step)
    return np.asarray(quantise.dequantise(q, step, origin), np.float32).astype(np.float64)


def with_bone_layer(coefficients: bytes, enc: Any) -> bytes:
    """The coefficients part with the bone layer's keys and arrays added (format 1.1, ``required``), its
    other arrays packed as before."""
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
