"""Poses -> dynamic-PDE clip: options, curves, fit (fixed segments or error targets), encoding, report.

The fit is measured honestly: after encoding, the clip is decoded from its float32 parts and evaluated at
every source frame, and those positions give the errors in the report.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from .. import container
from ..clip import ClipParts
from ..container import ZSTD_LEVEL
from ..curves.split import split_curves
from ..curveset import CurveSet
from ..errors import ParameterError, PosesInputError
from ..poses import Poses
from ..progress import Progress, sub_progress
from .adaptive import Targets, fit_adaptive
from .clipformat import (
    FORMAT_VERSION,
    FORMAT_VERSIONS,
    TRIAL_LEVEL,
    CoefficientData,
    encode_coefficients,
    encode_topology,
)
from .clipmodel import clip_from_parts
from .fitcore import (
    SpaceStage,
    TimeStage,
    floor_distances,
    items_from_curves,
    model_distances,
    space_stage,
    time_stage,
    vertex_slots,
)
from .metrics import bbox_diagonal, error_summary
from .parameterisation import PARAM_MODES, curve_parameters
from .quantise import power_of_two_step
from .rigid import RigidTracks, fit_rigid, local_residual
from .segments import DEFAULT_MAX_SEGMENTS, Segmentation, normalised_times, uniform_segmentation
from .tangents import CATMULL_ROM, NATURAL, prefer_tangents

MOTIONS = ("displacement", "absolute", "rigid")
DEFAULT_TARGET_REL_RMS = 3e-3


@dataclass
class FitOptions:
    """What to fit and how well. Give error targets or a fixed segment count (not both); none = rel RMS 3e-3.

    target_rms / target_max : absolute per-vertex distance; target_rel_rms / target_rel_max : relative to
    the first frame's bounding-box diagonal. param_mode "chord" | "paper"; motion "displacement" |
    "absolute" | "rigid" (per-curve rigid tracks + residual in the curve's frame); loop: periodic knots (last
    frame flows into the first); max_segments caps the adaptivity (reaching it is reported, never silent).
    best_effort: a missed target is not an error (the CLI exits 0, a fit job succeeds with the best clip).
    format_version: 5 (as 3, plus natural-spline time tangents for the items whose motion they predict
    better; a clip without any is written as version 3), 4 (the same with Catmull-Rom tangents), 3
    (integer-coded, rounding by at most QUANT_SHARE of the target, knots on a shared time basis where that is
    smaller; such a clip without the basis is written as version 2), 2 (the same without the basis) or 1
    (float32).
    """

    target_rms: float | None = None
    target_rel_rms: float | None = None
    target_max: float | None = None
    target_rel_max: float | None = None
    segments: int | None = None
    param_mode: str = "chord"
    motion: str = "displacement"
    loop: bool = False
    max_segments: int = DEFAULT_MAX_SEGMENTS
    curve_points: int = 10
    best_effort: bool = False
    format_version: int = FORMAT_VERSION

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> FitOptions:
        """Raise ParameterError on a bad value; returns self."""
        for name in ("target_rms", "target_rel_rms", "target_max", "target_rel_max"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int | float) and not isinstance(v, bool)
                                      and np.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be a positive number, got {v!r}")
        if self.segments is not None and not (
            isinstance(self.segments, int) and not isinstance(self.segments, bool) and self.segments >= 1
        ):
            raise ParameterError(f"segments must be an integer >= 1, got {self.segments!r}")
        if self.segments is not None and self.has_targets:
            raise ParameterError("give either a fixed segment count or error targets, not both")
        if self.param_mode not in PARAM_MODES:
            raise ParameterError(f"param_mode must be one of {PARAM_MODES}, got {self.param_mode!r}")
        if self.motion not in MOTIONS:
            raise ParameterError(f"motion must be one of {MOTIONS}, got {self.motion!r}")
        for name in ("loop", "best_effort"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if self.format_version not in FORMAT_VERSIONS or isinstance(self.format_version, bool):
            raise ParameterError(
                f"format_version must be one of {FORMAT_VERSIONS}, got {self.format_version!r}")
        for name in ("max_segments", "curve_points"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 4096):
                raise ParameterError(f"{name} must be an integer in 1..4096, got {v!r}")
        return self

    @property
    def has_targets(self) -> bool:
        """Whether any error target is set."""
        return any(getattr(self, n) is not None for n in ("target_rms", "target_rel_rms", "target_max",
                                                             "target_rel_max"))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitOptions:
        """Options from a JSON-like dict; unknown keys or bad values raise ParameterError."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ParameterError(f"unknown fit option(s): {', '.join(unknown)}")
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (round-trips through from_dict)."""
        return asdict(self)

    def targets(self, diagonal: float) -> Targets:
        """Absolute targets (the tighter of absolute and relative where both are given)."""
        def pick(a: float | None, rel: float | None) -> float | None:
            """The tighter of an absolute and a relative target (None if neither)."""
            vals = [v for v in (a, None if rel is None else rel * diagonal) if v is not None]
            return min(vals) if vals else None
        rel_rms = self.target_rel_rms
        if not self.has_targets and self.segments is None:
            rel_rms = DEFAULT_TARGET_REL_RMS
        return Targets(pick(self.target_rms, rel_rms), pick(self.target_max, self.target_rel_max))


def default_curves(rest: np.ndarray, faces: np.ndarray, curve_points: int = 10) -> CurveSet:
    """Curves of :func:`pdeanim.curves.extract.extract_curves` for the rest pose (V, 3) and faces (T, 3)."""
    from ..curves.extract import extract_curves

    return extract_curves(
        np.asarray(rest, np.float64), faces if len(faces) else None, target_points=curve_points
    )


@dataclass
class _Problem:
    """Padded data of one fit."""

    X: np.ndarray  # (F, V, 3) float32 source positions (the poses' own array: no float64 copy is kept)
    rest: np.ndarray  # (V, 3) float64 (float32 values)
    idx: np.ndarray
    mask: np.ndarray
    u: np.ndarray  # (C, 3, N)
    Y: (
        np.ndarray
    )  # (F, K, N) float64 what the curves fit (displacement, positions or rigid residual) as items
    t: np.ndarray  # (F,) normalised times
    rigid: RigidTracks | None = None
    slots: np.ndarray | None = None  # (V,) slot c * N + n of every vertex in the padded curves


def _prepare(poses: Poses, options: FitOptions, curves: CurveSet) -> _Problem:
    X = np.asarray(poses.vertices, np.float32)  # float64 copies of all frames are made only transiently
    times = np.asarray(poses.times, np.float64)
    if len(X) == 1:  # a single frame: a static clip over a unit time span
        X, times = np.concatenate([X, X]), np.array([times[0], times[0] + 1.0])
    rest = X[0].astype(np.float64)
    idx, mask = curves.padded()
    u = curve_parameters(X[:, idx].astype(np.float64) if options.param_mode == "paper" else rest[idx], mask,
                         options.param_mode)
    grid = u_grid(mask.shape[1])
    u = np.rint(u / grid) * grid  # on the grid version 2 stores exactly: rounding u costs no error
    t = (times - times[0]) / (times[-1] - times[0])
    rigid = None
    if options.motion == "rigid":
        X64 = X.astype(np.float64)
        rigid = fit_rigid(rest[idx], X64[:, idx], mask, t, options.loop)
        values = local_residual(X64, rest, curves.curve_of_vertex(len(rest))[0], rigid, t)
        del X64
    else:
        values = X - rest if options.motion == "displacement" else X
    Y = items_from_curves(values, idx, mask)
    del values
    return _Problem(X, rest, idx, mask, u, Y, t, rigid, vertex_slots(idx, mask, X.shape[1]))


def _distances(p: _Problem, space: SpaceStage, time_: TimeStage) -> np.ndarray:
    """(F, V) model-to-data distances (for rigid motion measured in the curves' frames: the same lengths)."""
    return model_distances(space, time_, p.slots)


def _floor_distances(p: _Problem, space: SpaceStage) -> np.ndarray:
    return floor_distances(space, p.slots)


@dataclass
class _SpaceFit:
    """The space stage of a fit and what it was measured on."""

    p: _Problem
    curves: CurveSet
    space: SpaceStage
    floor_d: np.ndarray  # (F, V) distance left by the space basis alone
    targets: Targets
    diag: float
    curve_points: int | None
    splits: int = 0


def _space_fit(poses: Poses, options: FitOptions, curves: CurveSet | None, progress: Progress) -> _SpaceFit:
    """Curves + space stage; automatic curves get shorter until the spatial floor's RMS leaves room for the
    target, then the curves whose floor exceeds the per-vertex bound are split (see SPLIT_RMS_RATIO)."""
    auto = curves is None
    for cp in _curve_point_ladder(options.curve_points if auto else None):
        progress(0.02, f"curves {cp or 'given'}")
        cs = _checked_curves(default_curves(poses.vertices[0], poses.faces, cp) if auto else curves,
                             poses.n_vertices)
        p, space, floor_d = _space_of(poses, options, cs, progress)
        diag = bbox_diagonal(p.rest)
        targets = options.targets(diag)
        if options.segments or _floor_leaves_room(floor_d, targets):
            break
    splits = 0
    bound = None if options.segments or not auto else _curve_floor_bound(targets)
    for _ in range(SPLIT_ROUNDS if bound is not None else 0):
        bad = _curve_max(cs, floor_d) > bound
        new = split_curves(p.rest, cs, bad) if bad.any() else cs
        if new.n_curves == cs.n_curves:
            break
        splits += new.n_curves - cs.n_curves
        progress(0.06, f"split {new.n_curves - cs.n_curves} curves")
        cs = new
        del p, space, floor_d  # one problem held at a time
        p, space, floor_d = _space_of(poses, options, cs, progress)
    return _SpaceFit(p, cs, space, floor_d, targets, diag, cp, splits)


def _space_of(poses: Poses, options: FitOptions, cs: CurveSet, progress: Progress
              ) -> tuple[_Problem, SpaceStage, np.ndarray]:
    """Problem, space stage and floor distances (F, V) of one curve set."""
    p = _prepare(poses, options, cs)
    K, N = p.Y.shape[1], p.Y.shape[2]
    progress(0.05, "space fit")
    space = space_stage(p.Y, p.u.reshape(K, N), np.repeat(p.mask, 3, axis=0))
    if options.format_version >= 4 and not options.loop:
        space.tangent_rule = NATURAL if options.format_version >= 5 else CATMULL_ROM
        space.tangents = prefer_tangents(space.b, p.t, space.tangent_rule)
    return p, space, _floor_distances(p, space)


def _curve_max(cs: CurveSet, d: np.ndarray) -> np.ndarray:
    """(C,) largest distance (F, V) on each curve."""
    out = np.zeros(cs.n_curves)
    np.maximum.at(out, cs.curve_of_vertex(d.shape[1])[0], d.max(axis=0))
    return out


def _curve_floor_bound(targets: Targets) -> float | None:
    """The most a curve's spatial floor may leave at any vertex before it is split in two."""
    bounds = []
    if targets.max is not None:
        bounds.append(FLOOR_MAX_SHARE * targets.max)
    if targets.rms is not None and SPLIT_RMS_RATIO is not None:
        bounds.append(SPLIT_RMS_RATIO * targets.rms)
    return min(bounds) if bounds else None


def fit_poses(poses: Poses, options: FitOptions | None = None, progress: Progress | None = None,
              curves: CurveSet | None = None) -> ClipParts:
    """Fit a dynamic-PDE clip to poses (F frames, V vertices); returns both parts and a report."""
    options = (options or FitOptions()).validate()
    t_start = time.perf_counter()
    report_progress = sub_progress(progress, 0.0, 1.0)
    sf = _space_fit(poses, options, curves, report_progress)
    p, space = sf.p, sf.space
    t_space = time.perf_counter()
    best = _candidate(p, sf, options, poses, sub_progress(progress, 0.1, 0.85))
    dense = min(len(p.t) - 1, options.max_segments)
    if (not options.segments and options.format_version >= 2 and best.meets
            and DENSE_FROM * (len(p.t) - 1) <= best.fitted.segm.n_segments < dense):
        report_progress(0.86, f"dense fit ({dense} segments)")
        cand = _candidate(p, sf, options, poses, None, dense)
        if cand.meets and _preferred(p, sf, options, poses, cand, best):
            best = cand
    t_time = time.perf_counter()
    report_progress(0.97, "report")
    fitted, quant = best.fitted, best.quant
    report = _report(p, best.approx, best.exact, sf.floor_d, fitted, sf.targets, best.met, best.floor_high,
                     best.history, options, sf.curves, sf.diag, poses)
    report["curve_points"] = sf.curve_points
    report["curve_splits"] = sf.splits
    report["dense_fit"] = best.dense is not None
    report["segment_cap_reached"] = bool(best.cap) and not best.meets
    report["every_frame_a_knot"] = bool(best.unsplittable)
    t_end = time.perf_counter()
    report["timings_s"] = {"curves_and_space": t_space - t_start, "time_and_encode": t_time - t_space,
                           "report": t_end - t_time, "total": t_end - t_start}
    report["quantisation_tolerance"] = quant.tolerance
    report["quantisation_knot_rms"] = quant.knot_rms
    report["quantisation_knot_cap"] = quant.knot_cap
    parts = _encode(p, sf.curves, space, fitted, options, poses, _header_errors(report), quant)
    header = container.unpack(parts.coefficients)[0]
    report["format_version"] = header["format_version"]
    report["knot_rank"] = header.get("knot_rank")  # shared time tracks of version 3, None without
    report["tangent_items"] = 0 if fitted.tangents is None else int(fitted.tangents.sum())  # cubic (v4)
    parts.report = {**report, "sizes": parts.sizes(poses.n_frames, poses.n_vertices)}
    report_progress(1.0, "done")
    return parts


CLOSE_SIZES = 0.15
"""Candidates whose trial sizes lie within this share of each other are close: the one with a clearly lower
max error is kept (AnimatedMorphSphere at 3e-3: 9.6 KB with rel-max 0.0048 instead of 9.2 KB with 0.024),
else they are compared at the final zstd level (trial sizes can tie where the final ones differ: pdance at
3e-3, 452 KB both at level 3, 358 KB against 405 KB at level 19)."""
CLEARLY_LOWER_MAX = 0.75
"""A close candidate's max error is clearly lower below this share of the other's."""


def _preferred(p: _Problem, sf: _SpaceFit, options: FitOptions, poses: Poses, a: _Candidate, b: _Candidate
               ) -> bool:
    """Whether candidate ``a`` is kept over ``b``: the one within the soft max bound of an RMS target if only
    one is (see SOFT_MAX_RATIO), else the smaller, or of two close in size the one with a clearly lower max
    error, else the smaller at the final zstd level."""
    F = poses.n_frames
    worst = [float(np.linalg.norm(c.approx[:F].astype(np.float64) - p.X[:F], axis=-1).max()) for c in (a, b)]
    soft = _soft_max(sf.targets)
    if soft is not None and (worst[0] <= soft) != (worst[1] <= soft):
        return worst[0] <= soft
    if abs(a.size - b.size) > CLOSE_SIZES * min(a.size, b.size):
        return a.size < b.size
    if worst[0] < CLEARLY_LOWER_MAX * worst[1] or worst[1] < CLEARLY_LOWER_MAX * worst[0]:
        return worst[0] < worst[1]

    def final(c: _Candidate) -> int:
        parts = _encode(p, sf.curves, sf.space, c.fitted, options, poses, None, c.quant)
        return len(parts.topology) + len(parts.coefficients)

    return final(a) < final(b)


DENSE_FROM = 0.0
"""When the error-driven fit needs segments for at least this share of the frame intervals (by default:
always), a dense fit (a knot at every frame, or max_segments evenly spaced) is tried too and the smaller
stored clip that meets the targets is kept: a dense fit is far more accurate, which leaves most of the target
to the knots' rounding, and its smooth knot tracks code small (elephant-gallop at 3e-3: 35 segments 659 KB,
47 segments 429 KB; samba: 28 segments 688 KB, 174 segments 551 KB; both with a 4x lower max error;
horse-collapse keeps its 5 segments for 52 frames)."""


@dataclass
class _Candidate:
    """One time fit (at a share of the targets) and its stored clip."""

    dense: int | None  # the segment count of a dense fit, None for the error-driven or fixed one
    fitted: TimeStage
    met: bool | None
    floor_high: bool
    history: list
    cap: bool
    unsplittable: bool
    exact: np.ndarray
    quant: _Quantisation
    approx: np.ndarray
    size: int
    meets: bool


def _candidate(p: _Problem, sf: _SpaceFit, options: FitOptions, poses: Poses, progress: Progress | None,
               dense: int | None = None) -> _Candidate:
    """A time fit (error-driven, fixed segments, or ``dense`` evenly spaced segments) rounded and measured on
    the targets."""
    if options.segments or dense:
        every = dense is not None and dense >= len(p.t) - 1
        segm = Segmentation(np.arange(len(p.t)), normalised_times(p.t)) if every else uniform_segmentation(
            p.t, options.segments or dense)
        fitted, met, floor_high, history = time_stage(sf.space, segm, options.loop), None, False, []
        cap = unsplittable = False
    else:
        res = fit_adaptive(sf.space, Segmentation(np.array([0, len(p.t) - 1]), p.t), sf.targets,
                           lambda ts: _distances(p, sf.space, ts), sf.floor_d,
                           min(options.max_segments, len(p.t) - 1), options.loop, progress)
        fitted, met, floor_high, history = res.time, res.met, res.floor_exceeds_target, res.history
        cap, unsplittable = res.cap_reached, res.unsplittable
    exact = _distances(p, sf.space, fitted)
    quant, approx, size = _quantised(p, sf, sf.space, fitted, options, poses, exact)
    F = poses.n_frames
    meets = _meets(sf.targets, np.linalg.norm(approx[:F].astype(np.float64) - p.X[:F], axis=-1))
    if dense:
        met = meets
    return _Candidate(dense, fitted, met, floor_high, history, cap, unsplittable, exact, quant, approx, size,
                      meets)


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


def _curve_point_ladder(start: int | None) -> list[int | None]:
    """Curve lengths tried when curves are extracted automatically: shorter until the floor leaves room."""
    if start is None:
        return [None]
    ladder = [start]
    while ladder[-1] > 3:
        ladder.append(max(3, int(round(ladder[-1] * 0.7))))
    return ladder


SPLIT_RMS_RATIO: float | None = 2.0
"""With an RMS target, an automatically extracted curve whose spatial floor leaves more than this times the
target at some vertex is split in two (repeatedly): an RMS-driven fit bounds no single vertex, and the
curves' floor is where the largest errors come from (one-off fits at 1e-3 with 2.5, before the soft max
bound: rel-max horse-collapse 0.0064 -> 0.0031, samba 0.0096 -> 0.0041, pdance 0.0071 -> 0.0046,
elephant-gallop 0.0056 -> 0.0046, for 1-6% more bytes; the rest of the max error is the knots' rounding).
None: no such split."""
SPLIT_ROUNDS = 12
"""Rounds of splitting at most (each halves the offending curves; 12 reach single points from 4096)."""
FLOOR_MAX_SHARE = 0.7
"""With a max target, curves are split until their floor leaves at most this share of it at every vertex
(the rest is the time fit's and the rounding's)."""


def _floor_leaves_room(floor_d: np.ndarray, targets: Targets) -> bool:
    """Whether the spatial floor's RMS is far enough below an RMS target for the time fit to meet it (a max
    target is left to splitting the curves that exceed it)."""
    ok_rms = targets.rms is None or np.sqrt(np.mean(floor_d * floor_d)) <= 0.5 * targets.rms
    return bool(ok_rms)


def _checked_curves(curves: CurveSet, n_vertices: int) -> CurveSet:
    curves = CurveSet(np.asarray(curves.order, np.int32), np.asarray(curves.offsets, np.int32))
    try:
        return curves.validate(n_vertices)
    except Exception as exc:
        raise PosesInputError(f"curves do not match the poses: {exc}") from exc


def u_grid(points_per_curve: int) -> float:
    """Grid of the curve parameters, applied before the fit so that format version 2 stores them exactly and
    cheaply: 2^-12, or finer for long curves (at least 256 steps between evenly spaced points)."""
    return 2.0 ** -max(12, int(np.ceil(np.log2(max(points_per_curve, 1)))) + 8)
QUANT_SHARE = 0.1
"""Format version 2 rounds the rest pose (and, for max targets, the knots) by at most this share of the
fit's tightest target per coordinate."""
QUANT_BUDGET = 0.8
"""With an RMS target only, the knots' rounding may take this share of what the fit leaves of the target
(target^2 - fit rms^2, less the rest pose's share)."""
KNOT_CAP = 2.0
"""With an RMS budget for the knots' rounding, no vertex coordinate moves by more than this times it."""
QUANT_RETRIES = 6
QUANT_FILL = 0.9
"""The knots' rounding grows while the stored clip's RMS stays below this share of an RMS target."""
BISECT_UNTIL = 1.15
"""When a grown rounding misses the target, the budget is bisected (geometric mean) between it and the last
one that met it while they differ by more than this factor (and retries remain)."""
QUANT_AIM = 0.95
"""Each growth aims the stored clip's RMS at this share of the target: the rounding's share of the mean
square error is taken as proportional to the knots' budget squared (between x 1.2 and x 4 per step)."""


@dataclass
class _Quantisation:
    """How the stored clip is rounded: per-coordinate tolerance (rest; knots unless knot_rms), the RMS budget
    of the knots' rounding and the most it may move a vertex coordinate."""

    tolerance: float | None = None
    knot_rms: float | None = None
    knot_cap: float | None = None
    cap_limit: float = np.inf

    def finer(self) -> _Quantisation:
        """Half the rounding error."""
        def half(x: float | None) -> float | None:
            return None if x is None else x / 2
        return _Quantisation(half(self.tolerance), half(self.knot_rms), half(self.knot_cap), self.cap_limit)

    def coarser(self, factor: float) -> _Quantisation:
        """``factor`` x the knots' rounding (the cap no further than what a max target leaves)."""
        assert self.knot_rms is not None and self.knot_cap is not None
        return _Quantisation(self.tolerance, factor * self.knot_rms,
                             min(factor * self.knot_cap, self.cap_limit), self.cap_limit)


def _first_quantisation(targets: Targets, exact: np.ndarray, options: FitOptions) -> _Quantisation:
    """Rounding for format version 2: a share of the tightest target per coordinate; with an RMS target, the
    knots get most of what the unrounded fit leaves of it, moving no vertex by more than KNOT_CAP times that
    budget nor by more than what it leaves of a max target."""
    goals = [g for g in (targets.rms, targets.max) if g is not None]
    if options.format_version < 2 or not goals:
        return _Quantisation()
    tolerance = QUANT_SHARE * min(goals)
    if targets.rms is None:
        return _Quantisation(tolerance)
    rest_step = power_of_two_step(tolerance)
    spare = QUANT_BUDGET * (targets.rms**2 - float(np.mean(exact * exact))) - rest_step**2 / 4
    if spare <= tolerance**2:
        return _Quantisation(tolerance)
    knot_rms = float(np.sqrt(spare))
    limit = np.inf
    if targets.max is not None:  # what the fit leaves of the max target, shared by the rest and the knots
        limit = max(tolerance, (targets.max - float(exact.max(initial=0.0))) / (2 * np.sqrt(3)))
    return _Quantisation(tolerance, knot_rms, min(KNOT_CAP * knot_rms, limit), limit)


def _quantised(p: _Problem, sf: _SpaceFit, space: SpaceStage, fitted: TimeStage, options: FitOptions,
               poses: Poses, exact: np.ndarray) -> tuple[_Quantisation, np.ndarray, int]:
    """(rounding, decoded positions (F, V, 3), stored bytes) of the clip: the rounding halves while it alone
    makes a target missed that the unrounded fit met, and the knots' budget grows while the stored clip stays
    well inside an RMS target (the estimate of the noise is conservative)."""
    F = poses.n_frames
    quant = _first_quantisation(sf.targets, exact[:F], options)
    best, missed = None, None  # the coarsest rounding that met the targets; the finest grown one that did not
    soft = None  # the soft max bound, once the first rounding has kept within it (growth may not pass it)
    for _ in range(QUANT_RETRIES + 1):
        parts = _encode(p, sf.curves, space, fitted, options, poses, None, quant, TRIAL_LEVEL)
        clip = _decode(parts)
        approx = clip.evaluate(clip.frame_t())
        found = (quant, approx, len(parts.topology) + len(parts.coefficients))
        if quant.tolerance is None or not _meets(sf.targets, exact[:F]):
            return found
        d = np.linalg.norm(approx[:F].astype(np.float64) - p.X[:F], axis=-1)
        if best is None and _meets(sf.targets, d):
            bound = _soft_max(sf.targets)
            soft = bound if bound is not None and d.max(initial=0.0) <= bound else None
        if not _meets(sf.targets, d) or (soft is not None and d.max(initial=0.0) > soft):
            if best is None:
                quant = quant.finer()
                continue
            missed = quant
        else:
            best = found
            if quant.knot_rms is None or np.sqrt(np.mean(d * d)) > QUANT_FILL * sf.targets.rms:
                return best
        good = best[0]
        if missed is None:
            quant = good.coarser(_growth(float(np.mean(d * d)), float(np.mean(exact[:F] ** 2)),
                                         sf.targets.rms))
            continue
        gap = missed.knot_rms / good.knot_rms  # a grown rounding missed: halve the gap (in log) between them
        if gap < BISECT_UNTIL:
            return best
        quant = good.coarser(float(np.sqrt(gap)))
    return best or found


SOFT_MAX_RATIO: float | None = 3.5
"""An RMS target alone also asks, softly, that no vertex be off by more than this times it: the knots'
rounding grows only while the stored clip stays within that (when its first rounding did), and of two
candidate fits the one within it is kept. It is never reported as a missed target. None: no soft bound."""


def _soft_max(targets: Targets) -> float | None:
    """The soft max bound of an RMS target without a max target (see SOFT_MAX_RATIO), else None."""
    if SOFT_MAX_RATIO is None or targets.rms is None or targets.max is not None:
        return None
    return SOFT_MAX_RATIO * targets.rms


def _growth(stored: float, exact: float, target: float) -> float:
    """Factor on the knots' budget that should bring the stored mean square error ``stored`` to QUANT_AIM of
    the RMS ``target``, the rounding adding ``stored - exact`` (proportional to the budget squared)."""
    added = stored - exact
    if added <= 0:
        return 4.0
    return float(np.clip(np.sqrt(max((QUANT_AIM * target) ** 2 - exact, 0.0) / added), 1.2, 4.0))


def _meets(targets: Targets, d: np.ndarray) -> bool:
    """Whether per-vertex distances (F, V) meet the targets."""
    return bool((targets.rms is None or np.sqrt(np.mean(d * d)) <= targets.rms)
                and (targets.max is None or d.max(initial=0.0) <= targets.max))


def _coefficient_data(space: SpaceStage, fitted: TimeStage, options: FitOptions, times: np.ndarray,
                      errors: dict) -> CoefficientData:
    K = space.b.shape[0]
    C, S = K // 3, fitted.segm.n_segments
    mu = fitted.mu.reshape(C, 3, S)
    family = (2 * (mu < 0) + space.proj.kind.reshape(C, 3)[:, :, None]).astype(np.uint8)
    knots = fitted.knots.reshape(C, 3, S + 1, 4)
    tangents = None if fitted.tangents is None else fitted.tangents.reshape(C, 3).astype(np.uint8)
    return CoefficientData(fitted.segm.segment_t, times, np.moveaxis(family, 2, 0),
                           np.moveaxis(np.abs(mu), 2, 0), space.proj.D.reshape(C, 3),
                           np.moveaxis(knots, 2, 0), options.motion, options.loop, {"errors": errors},
                           tangents=tangents, spline_tangents=fitted.tangent_rule == NATURAL)


def _encode(p: _Problem, curves: CurveSet, space: SpaceStage, fitted: TimeStage, options: FitOptions,
            poses: Poses, errors: dict | None = None, quant: _Quantisation | None = None,
            level: int = ZSTD_LEVEL) -> ClipParts:
    V = p.X.shape[1]
    u_v = np.zeros((V, 3))
    u_v[p.idx[p.mask]] = np.moveaxis(p.u, 1, 2)[p.mask]
    version, quant = options.format_version, quant or _Quantisation()
    topology = encode_topology(curves, u_v, poses.faces, p.rest, options.param_mode, version, quant.tolerance,
                               level)
    coef = _coefficient_data(space, fitted, options, np.asarray(poses.times, np.float64), errors or {})
    if p.rigid is not None:
        coef.extra = p.rigid.arrays()
    return ClipParts(topology, encode_coefficients(topology, coef, version, quant.tolerance, quant.knot_rms,
                                                   quant.knot_cap, level))


def _decode(parts: ClipParts):
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    return clip_from_parts(th, ta, ch, ca)


def _header_errors(report: dict) -> dict:
    keys = ("rms", "max", "rel_rms", "rel_max", "kg", "floor_rel_rms", "target_met", "floor_exceeds_target")
    return {k: report[k] for k in keys if k in report}


def _report(p, approx, exact, floor_d, fitted, targets, met, floor_high, history, options, curves,
            diag, poses) -> dict[str, Any]:
    X = p.X[: poses.n_frames]
    approx = approx[: poses.n_frames]
    summary = error_summary(X, approx, diag)
    d = np.linalg.norm(approx.astype(np.float64) - X, axis=-1)  # (F, V)
    cid, _ = curves.curve_of_vertex(X.shape[1])
    n_c = np.bincount(cid, minlength=curves.n_curves) * len(X)
    curve_rms = np.sqrt(np.bincount(cid, (d * d).sum(0), minlength=curves.n_curves) / np.maximum(n_c, 1))
    curve_max = np.zeros(curves.n_curves)
    np.maximum.at(curve_max, cid, d.max(0))
    floor_rms = float(np.sqrt(np.mean(floor_d * floor_d)))
    met_now = bool(
        (targets.rms is None or summary["rms"] <= targets.rms)
        and (targets.max is None or summary["max"] <= targets.max)
    )
    return {
        **summary,
        "frames": int(poses.n_frames),
        "vertices": int(X.shape[1]),
        "curves": curves.n_curves,
        "segments": fitted.segm.n_segments,
        "segment_t": fitted.segm.segment_t.tolist(),
        "segment_frames": fitted.segm.bounds.tolist(),
        "per_frame_rms": np.sqrt(np.mean(d * d, axis=1)).tolist(),
        "per_frame_max": d.max(axis=1).tolist(),
        "per_curve_rms": curve_rms.tolist(),
        "per_curve_max": curve_max.tolist(),
        "floor_rms": floor_rms,
        "floor_rel_rms": floor_rms / diag,
        "floor_max": float(floor_d.max()),
        "float32_vs_float64_max": float(np.abs(d - exact[: len(d)]).max()),
        "targets": {"rms": targets.rms, "max": targets.max},
        "target_met": met_now if met is not None else None,
        "floor_exceeds_target": bool(floor_high),
        "adaptive_history": history,
        "options": options.to_dict(),
    }


def curve_errors(poses: Poses, curves: CurveSet, options: FitOptions | None = None) -> dict[str, np.ndarray]:
    """Per-curve errors of fitting poses with the given curves: {"rms": (C,), "max": (C,), "floor_rms": (C,)}.

    For error-bounded curve extraction: fit, then read which curves stay above a target.
    """
    parts = fit_poses(poses, options, curves=curves)
    r = parts.report
    p = _prepare(poses, options or FitOptions(), curves)
    K, N = p.Y.shape[1], p.Y.shape[2]
    space = space_stage(p.Y, p.u.reshape(K, N), np.repeat(p.mask, 3, axis=0))
    fd = _floor_distances(p, space)
    cid, _ = curves.curve_of_vertex(p.X.shape[1])
    n_c = np.bincount(cid, minlength=curves.n_curves) * len(fd)
    floor_rms = np.sqrt(np.bincount(cid, (fd * fd).sum(0), minlength=curves.n_curves) / np.maximum(n_c, 1))
    return {
        "rms": np.asarray(r["per_curve_rms"]),
        "max": np.asarray(r["per_curve_max"]),
        "floor_rms": floor_rms,
    }
