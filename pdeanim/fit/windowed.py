"""A fit of a long or large input in windows of frames, as steps that any process may run: the windows are
independent but for two joins, and each window chooses its segments as a one-piece fit does.

1. :func:`plan_windows`: the curves (chosen on a subsample of the frames), the rest pose's rounding and the
   window bounds;
2. :func:`gram_window` per window, then :func:`join_space`: the space family and constant of every item from
   its Gram matrix summed over all frames, and its time model (natural spline or the paper's pair: the
   spline runs over all knots of the clip, so it is one choice for every window) from the summed Gram
   matrices of what lines and the spline miss predicting every other frame;
3. :func:`encode_window` per window: the one-piece fit's time search and rate control
   (:func:`pdeanim.fit.search.best_candidate`: error-driven segments against a knot at every frame, the
   smaller stored clip that meets the targets) on the window's frames, with its first and last frames as
   knots and its own knot steps, so that every window meets the targets alone;
4. :func:`join_clip`: the windows' knots one after the other (a linear segment between two windows' end
   knots: the clip is continuous and no frame lies inside it), their steps per window (``knot_windows``,
   format §3.3-3.4, plain tracks: the format's per-window steps need knot_rank 0) and both parts.

Every step's result has ``to_bytes``/``from_bytes`` so that a job queue can hand windows to other workers
(service: one task per window). Memory of a step: one window of frames (an in-memory fit of them), never all
frames.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .. import container
from ..clipparts import ClipParts, topology_id
from ..curveset import CurveSet
from ..errors import InputError
from ..model import quantise
from ..model.adaptive import Targets
from ..model.clipformat import SHARED_KEY, TIME_SPLINE, decode_topology, topology_arrays
from ..model.coefwriter import CoefficientFields, KnotCodes, write_coefficients
from ..model.fitcore import SpaceStage, floor_distances, items_from_curves, vertex_slots
from ..model.knotbasis import SharedWeights
from ..model.metrics import bbox_diagonal
from ..model.parameterisation import curve_parameters
from ..model.spacefit import SpaceProjection, project_items, search_D
from ..model.spline import spline_residuals
from ..npzread import release_pages
from ..poses import Poses, make_poses
from ..progress import Progress, sub_progress
from .encode import unpacked_coefficients
from .options import FitOptions, FitTolerances
from .problem import prepare, stored_distances, u_grid
from .ratecontrol import Errors, first_quantisation
from .report import FitReport, time_model_counts
from .search import best_candidate, candidate
from .spacestage import SpaceFit, space_fit

CURVE_FRAMES = 128
"""Frames, evenly spaced, on which the curves of a windowed fit are chosen, at most ..."""
CURVE_VALUES = 1 << 20
"""... and at most this many frame-vertex values (an in-memory space fit takes a few hundred bytes each), but
at least MIN_WINDOW_FRAMES frames."""
MIN_WINDOW_FRAMES = 8
"""Frames per window at least (the time-model evidence needs a few frames on either side)."""
SHARED_RANK = 16
"""Shapes of motion, at most, that every window may put its knots on (:class:`SharedWeights`: the principal
shapes of the frames the curves are chosen on), stored once in the clip instead of a time basis with its own
weights per window (AnimatedMorphSphere in 8 windows: 11 ranks of weights, 6.1 KB of an 8.4 KB one-piece
clip)."""


def windowed_applies(n_frames: int, n_vertices: int, options: FitOptions, tol: FitTolerances) -> bool:
    """Whether a fit of (n_frames, n_vertices) poses runs in windows: inputs of more than
    tol.window_fit_values frame-vertex values, fitted with targets, displacement or absolute motion, chord
    parameters and an open clip, without a bone layer (the other fits need every frame at once; a bone fit's
    residual may then be fitted in windows)."""
    return (n_frames * n_vertices > tol.window_fit_values and tol.dense_fit
            and not options.segments and not options.loop and options.motion != "rigid"
            and options.param_mode == "chord" and options.bones == 0)


def curve_frames(n_frames: int, n_vertices: int) -> int:
    """Frames on which a windowed fit of (n_frames, n_vertices) poses chooses its curves."""
    return min(n_frames, CURVE_FRAMES, max(MIN_WINDOW_FRAMES, CURVE_VALUES // max(n_vertices, 1)))


def window_bounds(n_frames: int, n_vertices: int, tol: FitTolerances) -> np.ndarray:
    """(W+1,) first frame of every window, then n_frames: as few windows of at most tol.window_values
    frame-vertex values (and at least MIN_WINDOW_FRAMES frames) as cover the frames, of balanced sizes."""
    most = max(MIN_WINDOW_FRAMES, tol.window_values // max(n_vertices, 1), 1)
    W = max(1, min(-(-n_frames // most), n_frames // MIN_WINDOW_FRAMES))
    return np.round(np.linspace(0, n_frames, W + 1)).astype(np.int64)


def _pack(kind: str, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> bytes:
    return container.pack({"windowed_step": kind, **header}, arrays)


def _unpack(kind: str, blob: bytes) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    header, arrays = container.unpack(blob)
    if header.get("windowed_step") != kind:
        raise InputError(f"expected a windowed fit's {kind!r}, got {header.get('windowed_step')!r}")
    return header, arrays


@dataclass
class Layout:
    """The curves of a windowed fit and everything per vertex that does not depend on the frame."""

    curves: CurveSet
    idx: np.ndarray  # (C, N) vertex of each padded curve point
    mask: np.ndarray  # (C, N)
    u: np.ndarray  # (C, 3, N) curve parameters on the storage grid
    slots: np.ndarray  # (V,) c * N + n of every vertex
    curve_of: np.ndarray  # (V,)
    rest: np.ndarray  # (V, 3) float64 (float32 values): frame 0
    absolute: bool

    @classmethod
    def of(cls, curves: CurveSet, rest: np.ndarray, absolute: bool) -> Layout:
        """The layout of ``curves`` on the rest pose (chord parameters rounded to the storage grid)."""
        rest = np.asarray(np.asarray(rest, np.float32), np.float64)
        idx, mask = curves.padded()
        u = curve_parameters(rest[idx], mask, "chord")
        grid = u_grid(mask.shape[1])
        u = np.rint(u / grid) * grid
        return cls(curves, idx, mask, u, vertex_slots(idx, mask, len(rest)),
                   curves.curve_of_vertex(len(rest))[0], rest, absolute)

    @property
    def n_items(self) -> int:
        return self.mask.shape[0] * 3

    def items(self, frames: np.ndarray) -> np.ndarray:
        """(w, K, N) float64 what the curves fit of frames (w, V, 3): displacement or positions."""
        values = frames if self.absolute else frames - self.rest.astype(np.float32)
        return items_from_curves(values, self.idx, self.mask)

    def item_rows(self, frames: np.ndarray) -> np.ndarray:
        """(K, w, N) the same, item first."""
        return np.moveaxis(self.items(frames), 0, 1)

    def u_per_vertex(self) -> np.ndarray:
        """(V, 3) curve parameter of every vertex and coordinate."""
        u_v = np.zeros((len(self.rest), 3))
        u_v[self.idx[self.mask]] = np.moveaxis(self.u, 1, 2)[self.mask]
        return u_v


@dataclass
class WindowPlan:
    """What every step of a windowed fit shares: options, curves, rest pose, rounding of the rest pose (the
    topology part), window bounds and frame times."""

    options: FitOptions
    tol: FitTolerances
    layout: Layout
    bounds: np.ndarray  # (W+1,) int64
    times: np.ndarray  # (F,) float64
    topology: bytes
    tolerance: float | None
    diagonal: float
    report: dict[str, Any] = field(default_factory=dict)
    patterns: np.ndarray | None = None  # (r, V, 3) float32 principal shapes of the curves' frames (RMS size)

    @property
    def n_windows(self) -> int:
        return len(self.bounds) - 1

    @property
    def n_frames(self) -> int:
        return int(self.bounds[-1])

    def window(self, i: int) -> tuple[int, int]:
        """(first frame, end frame) of window i."""
        return int(self.bounds[i]), int(self.bounds[i + 1])

    @property
    def targets(self) -> Targets:
        return self.options.targets(self.diagonal)

    def base(self) -> np.ndarray:
        """(V, 3) float32 what the stored clip adds its knot fields to: the stored rest pose (zero for
        absolute motion)."""
        topo = decode_topology(*container.unpack(self.topology))
        return np.zeros_like(topo.rest) if self.layout.absolute else np.asarray(topo.rest, np.float32)

    def to_bytes(self) -> bytes:
        cs = self.layout.curves
        return _pack("plan", {"options": self.options.to_dict(), "tolerances": self.tol.to_dict(),
                              "tolerance": self.tolerance, "diagonal": self.diagonal, "report": self.report},
                     {"order": cs.order.astype(np.int32), "offsets": cs.offsets.astype(np.int32),
                      "rest": self.layout.rest.astype(np.float32), "bounds": self.bounds.astype(np.uint32),
                      "times": self.times, "topology": np.frombuffer(self.topology, np.uint8),
                      **({} if self.patterns is None else {"patterns": self.patterns.astype(np.float32)})})

    @classmethod
    def from_bytes(cls, blob: bytes) -> WindowPlan:
        h, a = _unpack("plan", blob)
        options = FitOptions.from_dict(h["options"])
        curves = CurveSet(a["order"].astype(np.int32), a["offsets"].astype(np.int32))
        return cls(options, FitTolerances(**h["tolerances"]),
                   Layout.of(curves, a["rest"], options.motion == "absolute"), a["bounds"].astype(np.int64),
                   a["times"], a["topology"].tobytes(), h["tolerance"], h["diagonal"], h["report"],
                   a.get("patterns"))


def plan_windows(poses: Poses, options: FitOptions, tol: FitTolerances, progress: Progress | None = None,
                 curves: CurveSet | None = None) -> WindowPlan:
    """Step 1: the curves (chosen on evenly spaced frames, CURVE_FRAMES and CURVE_VALUES at most, as an
    in-memory fit chooses them, unless given), the rest pose's rounding and the windows of ``poses``."""
    F, V = poses.n_frames, poses.n_vertices
    n_picked = curve_frames(F, V)
    picked = np.unique(np.round(np.linspace(0, F - 1, n_picked)).astype(np.int64))
    sub = make_poses(np.asarray(poses.vertices[picked]), poses.faces, poses.times[picked])
    sf = space_fit(sub, options, curves, progress or (lambda *_: None), tol)
    layout = Layout.of(sf.curves, poses.rest_pose(), options.motion == "absolute")
    diagonal = bbox_diagonal(layout.rest)
    tolerance = first_quantisation(options.targets(diagonal), 0.0, tol).tolerance
    header, arrays = topology_arrays(layout.curves, layout.u_per_vertex(), poses.faces, layout.rest,
                                     options.param_mode, tolerance)
    topology = container.pack(header, arrays, {n: container.SMALLEST for n in arrays})
    report = {"curve_points": sf.curve_points, "curve_splits": sf.splits, "curve_frames": int(len(picked))}
    shared = tol.knot_basis and tol.window_shared_weights
    patterns = _patterns(np.asarray(sub.vertices), layout) if shared else None
    return WindowPlan(options, tol, layout, window_bounds(F, V, tol), np.asarray(poses.times, np.float64),
                      topology, tolerance, diagonal, report, patterns)


def _patterns(frames: np.ndarray, layout: Layout) -> np.ndarray:
    """(r, V, 3) float32 the leading SHARED_RANK principal shapes (uncentred, as the knots are stored; each of
    its RMS size over the frames) of what the curves fit of ``frames`` (n, V, 3): displacement or
    positions."""
    n = len(frames)
    values = np.asarray(frames, np.float64).reshape(n, -1)
    if not layout.absolute:
        values = values - layout.rest.reshape(1, -1)
    energy, vectors = np.linalg.eigh(values @ values.T)
    order = np.argsort(energy)[::-1][:SHARED_RANK]
    keep = order[energy[order] > 1e-12 * max(float(energy.max(initial=0.0)), 1e-300)]
    shapes = (vectors[:, keep].T @ values) / np.sqrt(n)  # unit shapes times sqrt(energy / n)
    return shapes.reshape(len(keep), -1, 3).astype(np.float32)


@dataclass
class GramPart:
    """One window's share of the space stage: every item's Gram matrix (K, N, N) summed over the window's
    frames, the window's summed squared distance of the vertices to their frame's centroid, and for the time
    model the Gram matrices (K, N, N) float32 of what straight lines and the natural spline miss predicting
    every other frame (:func:`pdeanim.model.spline.spline_residuals`) and which items move (K,)."""

    gram: np.ndarray
    spread: float
    lin: np.ndarray
    cub: np.ndarray
    moving: np.ndarray

    def to_bytes(self) -> bytes:
        return _pack("gram", {"spread": self.spread},
                     {"gram": self.gram, "lin": self.lin, "cub": self.cub,
                      "moving": self.moving.astype(np.uint8)})

    @classmethod
    def from_bytes(cls, blob: bytes) -> GramPart:
        h, a = _unpack("gram", blob)
        return cls(a["gram"], float(h["spread"]), a["lin"], a["cub"], a["moving"].astype(bool))


def gram_window(plan: WindowPlan, frames: np.ndarray, index: int) -> GramPart:
    """Step 2, per window: the Gram matrices, spread and time-model evidence of ``frames`` (w, V, 3), window
    ``index``."""
    f0, f1 = plan.window(index)
    if len(frames) != f1 - f0:
        raise InputError(f"window {index} has {f1 - f0} frames, got {len(frames)}")
    Yk = plan.layout.item_rows(frames)  # (K, w, N)
    f = np.asarray(frames, np.float64)
    spread = float(((f - f.mean(axis=1, keepdims=True)) ** 2).sum())
    lin, cub = spline_residuals(Yk, _normalised(plan.times)[f0:f1])
    moving = np.ptp(Yk, axis=1).any(axis=-1)

    def gram_of(r: np.ndarray) -> np.ndarray:
        return (np.swapaxes(r, 1, 2) @ r).astype(np.float32)

    return GramPart(np.swapaxes(Yk, 1, 2) @ Yk, spread, gram_of(lin), gram_of(cub), moving)


@dataclass
class SpaceModel:
    """The space family (K,) and constant D (K,) of every item, its time model (K,) bool (the natural spline,
    else the paper's pair; one choice for every window, since the spline runs over all knots), and what the
    whole sequence's Gram matrices and spread gave (the floor's summed squared error, the Karni-Gotsman
    denominator)."""

    kind: np.ndarray
    D: np.ndarray
    gram_floor: float
    spread: float
    spline: np.ndarray
    shared: SharedWeights | None = None  # the knot weights every window may use (stored once in the clip)

    def projection(self, plan: WindowPlan) -> SpaceProjection:
        """The items' orthonormal space bases (the same, bit for bit, in every process)."""
        K, N = plan.layout.n_items, plan.layout.mask.shape[1]
        return project_items(plan.layout.u.reshape(K, N), np.repeat(plan.layout.mask, 3, axis=0),
                             self.kind, self.D, fallback=True)

    def to_bytes(self) -> bytes:
        shared = {} if self.shared is None else {"shared_codes": self.shared.codes.astype(np.int32),
                                                 "shared_grid": self.shared.grid.astype(np.float32)}
        return _pack("space", {"gram_floor": self.gram_floor, "spread": self.spread},
                     {"kind": self.kind.astype(np.uint8), "D": self.D.astype(np.float64),
                      "spline": self.spline.astype(np.uint8), **shared})

    @classmethod
    def from_bytes(cls, blob: bytes) -> SpaceModel:
        h, a = _unpack("space", blob)
        shared = None if "shared_codes" not in a else SharedWeights(
            a["shared_codes"].astype(np.int64), a["shared_grid"].astype(np.float64))
        return cls(a["kind"].astype(np.int64), a["D"], float(h["gram_floor"]), float(h["spread"]),
                   a["spline"].astype(bool), shared)


def join_space(plan: WindowPlan, parts: Iterable[GramPart]) -> SpaceModel:
    """Join 1: each item's space family and constant, as the in-memory space stage chooses them, from the Gram
    matrices summed over every window; and its time model, as the in-memory fit chooses its natural-spline
    candidates (:func:`pdeanim.model.spline.prefer_spline` on the projected tracks), from the summed Gram
    matrices of the prediction residuals."""
    lay = plan.layout
    K, N = lay.n_items, lay.mask.shape[1]
    gram, lin, cub, spread, moving = np.zeros((K, N, N)), np.zeros((K, N, N)), np.zeros((K, N, N)), 0.0, None
    for part in parts:
        gram += part.gram
        lin += part.lin
        cub += part.cub
        spread += part.spread
        moving = part.moving if moving is None else moving | part.moving
    u, mask = lay.u.reshape(K, N), np.repeat(lay.mask, 3, axis=0)
    kind, D, floor = search_D(u, mask, gram, check_cond=False)
    proj = project_items(u, mask, kind, D, fallback=True)
    options = plan.options
    if options.time_model == "auto":
        e_lin = np.einsum("kmn,kna,kma->k", lin, proj.U, proj.U)
        e_cub = np.einsum("kmn,kna,kma->k", cub, proj.U, proj.U)
        spline = (e_cub < plan.tol.cubic_gain * e_lin) & (e_lin > 0)
    elif options.time_model == "spline":
        spline = np.zeros(K, bool) if moving is None else moving
    else:
        spline = np.zeros(K, bool)
    return SpaceModel(np.asarray(proj.kind, np.int64), np.asarray(proj.D, np.float64), float(floor.sum()),
                      spread, np.asarray(spline, bool), _shared_weights(plan, proj))


def _shared_weights(plan: WindowPlan, proj: SpaceProjection) -> SharedWeights | None:
    """The plan's principal shapes as knot weights (r, C, 3, 4): the balanced space coefficients of each
    shape on the items' space bases, rounded to their grid (:class:`SharedWeights`)."""
    if plan.patterns is None or len(plan.patterns) == 0:
        return None
    lay = plan.layout
    Y = items_from_curves(plan.patterns, lay.idx, lay.mask)  # (r, K, N)
    z = np.einsum("rkn,kna->rka", Y, proj.U)
    a = np.einsum("kab,rkb->rka", proj.to_coef, z)
    return SharedWeights.of(a.reshape(len(a), lay.mask.shape[0], 3, 4))


SPLINE_GUARD = 6
"""Where a window meets another and some items are on the natural spline, its segment search starts with a
knot at each of this many frames next to the bound: the spline runs over all knots of the clip (format
§3.5.2), and a window fits and measures its own knots alone; with knots on the frames there, the clip's
values at the frames do not depend on the neighbour, and the neighbour's pull on the knot tangents decays
about 4x per knot before it reaches the window's longer segments (with 3 knots, the morph sphere in 4
windows was 1.09x off its measured max error in the middle of a 47-frame segment; with 6, 1.001x)."""
GUARD_MAX_SHARE = 0.98
"""... and such a window keeps its max error under this share of the soft max bound, for what is left."""


BASIS_MIN_FRAMES = 16
"""A window of fewer frames stores plain knot tracks: a shared basis of its own does not pay for its weights
and for the finest common step it imposes on every window (7 windows of 8 frames of a 162-vertex mesh: 14.3 KB
with bases, 10.7 KB without)."""


@dataclass
class WindowCodes:
    """One window's share of the clip: its knots' frames (S_w+1,), integer knot codes (C, 3, 4, S_w+1) (int16
    where they fit, else int32) on its own knot steps (C, 3), with a shared time basis of its own (format
    §3.4) its integer weights (r_w, C, 3, 4) and basis (r_w, S_w+1) float32 (the codes are then the residual;
    r_w may be 0), its segments' signed time constants (S_w, C, 3), its errors (stored clip and unrounded
    floor) and rate-control trials."""

    index: int
    codes: np.ndarray
    steps: np.ndarray
    knot_frames: np.ndarray
    m: np.ndarray
    weights: np.ndarray
    basis: np.ndarray
    frame_sq: np.ndarray  # (w,)
    frame_max: np.ndarray  # (w,)
    curve_sq: np.ndarray  # (C,)
    curve_max: np.ndarray  # (C,)
    floor_sq: float
    floor_max: float
    trials: list[dict]
    quantisation: dict[str, Any]

    _ARRAYS = ("codes", "steps", "knot_frames", "m", "weights", "basis", "frame_sq", "frame_max", "curve_sq",
               "curve_max")

    def to_bytes(self) -> bytes:
        return _pack("window", {"index": self.index, "floor_sq": self.floor_sq, "floor_max": self.floor_max,
                                "trials": self.trials, "quantisation": self.quantisation},
                     {n: getattr(self, n) for n in self._ARRAYS})

    @classmethod
    def from_bytes(cls, blob: bytes) -> WindowCodes:
        h, a = _unpack("window", blob)
        return cls(int(h["index"]), **{n: a[n] for n in cls._ARRAYS}, floor_sq=float(h["floor_sq"]),
                   floor_max=float(h["floor_max"]), trials=h["trials"], quantisation=h["quantisation"])


class WindowModel:
    """What the encoding of every window shares: the plan, the space model and the items' space bases (built
    once per process)."""

    def __init__(self, plan: WindowPlan, space: SpaceModel):
        self.plan, self.space = plan, space
        self.proj = space.projection(plan)


def encode_window(model: WindowModel, frames: np.ndarray, index: int, progress: Progress | None = None
                  ) -> WindowCodes:
    """Step 3, per window: the one-piece fit's time search and rate control on ``frames`` (w, V, 3; window
    ``index``) with the joined space model and time models: the error-driven segments against a knot at every
    frame, the smaller stored clip that meets the targets, on this window's own knot steps; its first and
    last frames are knots, so the windows meet at a segment between two frames (continuous, and no frame's
    value depends on another window's knots but through the spline's tangents, see SPLINE_GUARD)."""
    plan, lay, space = model.plan, model.plan.layout, model.space
    f0, f1 = plan.window(index)
    if len(frames) != f1 - f0:
        raise InputError(f"window {index} has {f1 - f0} frames, got {len(frames)}")
    options = plan.options
    poses = replace(make_poses(frames, None, plan.times[f0:f1]), rest=lay.rest.astype(np.float32))
    p = prepare(poses, options, lay.curves)
    Yk = np.moveaxis(p.Y, 0, 1)
    b = Yk @ model.proj.U
    floor = np.maximum(np.einsum("kfn,kfn->kf", Yk, Yk) - np.einsum("kfa,kfa->kf", b, b), 0.0)
    spline = space.spline
    tol = replace(plan.tol, quant_fill=plan.tol.window_quant_fill,
                  knot_basis=plan.tol.knot_basis and len(frames) >= BASIS_MIN_FRAMES)
    stage = SpaceStage(model.proj, b, floor, Yk, spline if spline.any() else None, np.inf,
                       space.shared if tol.knot_basis else None)
    floor_d = floor_distances(stage, p.slots)
    sf = SpaceFit(p, lay.curves, stage, floor_d, plan.targets, plan.diagonal, None)
    start = _start(plan, index, bool(spline.any()))
    if start is not None and tol.soft_max_ratio is not None:
        tol = replace(tol, soft_max_ratio=GUARD_MAX_SHARE * tol.soft_max_ratio)
    long = frames.shape[0] * frames.shape[1] > tol.window_search_values
    if tol.dense_fit and not options.segments and long:
        best = candidate(sf, options, poses, sub_progress(progress, 0.1, 0.85), tol,
                         min(len(frames) - 1, options.max_segments))  # long window: the dense fit alone
    else:
        best = best_candidate(sf, options, poses, progress, tol, start, lazy=True)
    quant = best.quant
    # the window's clip as its rate control measured it (the same encoding, decoded the same)
    _, header, arrays = unpacked_coefficients(p, lay.curves, stage, best.fitted, options, poses, quant)
    C = lay.curves.n_curves
    if not np.array_equal(arrays["time_model"].reshape(-1) == TIME_SPLINE, spline):
        raise RuntimeError(f"window {index} changed the time model of some items")  # the slack keeps them
    codes = quantise.decode_knot_tracks(arrays["knots"], int(header["knot_differences"]))
    rank = int(header["knot_rank"])
    weights = (quantise.unzigzag(arrays["knot_weights"]) if rank else np.zeros((0, C, 3, 4))).astype(np.int64)
    basis = arrays["knot_basis"] if rank else np.zeros((0, len(codes)), np.float32)
    d = stored_distances(p, best.approx, len(frames))  # (w, V): the window's stored clip, as measured
    dd = d * d
    fitted = best.fitted.segm
    return WindowCodes(
        index, _narrow_codes(np.moveaxis(codes, 0, -1)), arrays["knot_step"],
        (f0 + fitted.bounds).astype(np.int32), arrays["m"], weights.astype(np.int32), basis, dd.sum(axis=1),
        d.max(axis=1, initial=0.0), np.bincount(p.curve_of, dd.sum(axis=0), minlength=C),
        Errors.of(d, p.curve_of, C).curve_max, float((floor_d * floor_d).sum()),
        float(floor_d.max(initial=0.0)), best.trials,
        {"tolerance": quant.tolerance, "knot_rms": quant.knot_rms, "knot_cap": quant.knot_cap,
         "segments": fitted.n_segments, "dense": best.dense is not None, "knot_rank": rank,
         "shared_weights": bool(header.get(SHARED_KEY)), "met": bool(best.meets)})


def _narrow_codes(codes: np.ndarray) -> np.ndarray:
    """Knot codes (C, 3, 4, S_w+1) as int16 where they all fit (most windows), else int32: a windowed fit
    holds every window's codes until the join, which widens them exactly."""
    lo, hi = np.iinfo(np.int16).min, np.iinfo(np.int16).max
    small = codes.size == 0 or (codes.min() >= lo and codes.max() <= hi)
    return np.ascontiguousarray(codes, np.int16 if small else np.int32)


def _start(plan: WindowPlan, index: int, spline: bool) -> np.ndarray | None:
    """The boundaries (window frames) the segment search of window ``index`` starts from: its first and last
    frame, and with spline items a knot at each of SPLINE_GUARD frames next to a bound with another window."""
    f0, f1 = plan.window(index)
    n = f1 - f0 - 1
    if not spline or plan.n_windows == 1:
        return None
    g = min(SPLINE_GUARD, n // 2)
    bounds = {0, n}
    if index > 0:
        bounds.update(range(1, g + 1))
    if index < plan.n_windows - 1:
        bounds.update(range(n - g, n))
    return np.array(sorted(bounds), np.int64)


def _normalised(times: np.ndarray) -> np.ndarray:
    times = np.asarray(times, np.float64)
    span = times[-1] - times[0] if len(times) > 1 else 1.0
    return (times - times[0]) / span if span > 0 else np.zeros(len(times))


def join_clip(plan: WindowPlan, space: SpaceModel, windows: Sequence[WindowCodes],
              timings: dict[str, float] | None = None) -> ClipParts:
    """Join 2: the clip of every window's knots, one after the other (a linear segment between the last knot
    of a window and the first of the next: no frame lies inside it), on the windows' own knot steps
    (``knot_windows``), with the joined time models; both parts and the fit report. Each window's codes are
    released (set to None) once copied into the clip's."""
    W = plan.n_windows
    windows = sorted(windows, key=lambda w: w.index)
    if [w.index for w in windows] != list(range(W)):
        raise InputError(f"a windowed fit joins all {W} windows, got {[w.index for w in windows]}")
    lay, options = plan.layout, plan.options
    C, F = lay.curves.n_curves, plan.n_frames
    knot_frames = np.concatenate([w.knot_frames for w in windows]).astype(np.int64)
    first = np.concatenate([[0], np.cumsum([len(w.knot_frames) for w in windows])])  # (W+1,)
    S = len(knot_frames) - 1
    if not np.all(np.diff(knot_frames) > 0) or knot_frames[0] != 0 or knot_frames[-1] != F - 1:
        raise InputError("the windows' knots do not rise from the first frame to the last")
    m = np.zeros((S, C, 3), np.float32)  # the segments between windows are linear
    for i, w in enumerate(windows):
        m[first[i]:first[i + 1] - 1] = w.m
    knots = _joined_knots(windows, first, C, W)
    segment_t = _normalised(plan.times)[knot_frames]
    time_model = np.where(space.spline.reshape(C, 3), TIME_SPLINE, 0).astype(np.uint8)
    report = _report(plan, space, windows, knot_frames, time_model_counts(time_model, np.moveaxis(m, 0, -1)),
                     knots.rank)
    fields = CoefficientFields(segment_t, plan.times, space.kind.reshape(C, 3), time_model, m,
                               space.D.reshape(C, 3), options.motion, False)
    header, arrays = write_coefficients(fields, knots, topology_id(plan.topology),
                                        {"errors": report.header_errors()})
    coefficients = container.pack(header, arrays, {n: container.SMALLEST for n in arrays})
    parts = ClipParts(plan.topology, coefficients)
    report.timings_s = timings or None
    parts.report = {**report.to_dict(), "sizes": parts.sizes(F, lay.rest.shape[0])}
    return parts


def _joined_knots(windows: Sequence[WindowCodes], first: np.ndarray, C: int, W: int) -> KnotCodes:
    """The clip's knots from every window's, each decoding to the very knots its window measured: plain
    tracks on a step per window (``knot_windows``), or where some window stored its knots on a shared basis
    (which the format allows only with one step per item), one step per item, the finest of the windows'
    (powers of two, so a coarser window's codes and weights are exact multiples on it), and the windows'
    bases side by side, each zero outside its own knots (format §3.4: the zeros add nothing, so every knot
    sums its own window's terms in its window's order). Each window's codes are released once copied."""
    S1 = int(first[-1])
    shared = [bool(w.quantisation.get("shared_weights")) for w in windows]
    rank_shared = max([len(w.basis) for w, s in zip(windows, shared, strict=True) if s], default=0)
    rank = rank_shared + int(sum(len(w.basis) for w, s in zip(windows, shared, strict=True) if not s))
    if rank == 0:
        steps = windows[0].steps if W == 1 else np.stack([w.steps for w in windows])
        scale = [np.ones((C, 3), np.int64)] * W
    else:
        steps = np.min([w.steps for w in windows], axis=0)
        scale = [np.rint(np.asarray(w.steps, np.float64) / steps).astype(np.int64) for w in windows]
    codes = np.empty((C, 3, 4, S1), np.int32)
    weights = np.zeros((rank, C, 3, 4), np.int64)
    basis = np.zeros((rank, S1), np.float32)
    row, filled = rank_shared, 0  # the shared weights' rows first, then each own basis's
    for i, w in enumerate(windows):
        k = scale[i][:, :, None, None]
        scaled = w.codes.astype(np.int64) * k
        if np.abs(scaled).max(initial=0) > quantise.MAX_CODE:
            raise ValueError("knot codes out of range on the windows' common step")
        codes[..., first[i]:first[i + 1]], w.codes = scaled, None
        r = len(w.basis)
        wk = w.weights.astype(np.int64) * k[None, ..., 0]
        if np.abs(wk).max(initial=0) > quantise.MAX_CODE:
            raise ValueError("knot weights out of range on the windows' common step")
        if shared[i]:  # the same values in every window that uses them: stored once
            if not np.array_equal(weights[:min(r, filled)], wk[:min(r, filled)]):
                raise RuntimeError(f"window {w.index} changed the clip's shared knot weights")
            weights[filled:r] = wk[filled:r]
            filled = max(filled, r)
            basis[:r, first[i]:first[i + 1]] = w.basis
            continue
        weights[row:row + r] = wk
        basis[row:row + r, first[i]:first[i + 1]] = w.basis
        row += r
    order = quantise.difference_order(codes)
    tracks = quantise.track_codes(codes, order, in_place=True)
    if rank == 0:
        return KnotCodes(steps, tracks, order, windows=first if W > 1 else None)
    return KnotCodes(steps, tracks, order, quantise.zigzag(weights), basis)


def _report(plan: WindowPlan, space: SpaceModel, windows: Sequence[WindowCodes], knot_frames: np.ndarray,
            time_models: dict[str, int], knot_rank: int) -> FitReport:
    """The fit report of a windowed fit (an in-memory fit's, plus its windows)."""
    lay, targets, diag = plan.layout, plan.targets, plan.diagonal
    F, V, C = plan.n_frames, lay.rest.shape[0], lay.curves.n_curves
    frame_sq = np.concatenate([w.frame_sq for w in windows])
    frame_max = np.concatenate([w.frame_max for w in windows])
    curve_sq = np.sum([w.curve_sq for w in windows], axis=0)
    found = Errors(float(np.sqrt(frame_sq.sum() / (F * V))), float(frame_max.max(initial=0.0)),
                   np.max([w.curve_max for w in windows], axis=0))
    floor_rms = float(np.sqrt(sum(w.floor_sq for w in windows) / (F * V)))
    floor = Errors(floor_rms, max(w.floor_max for w in windows), np.zeros(C))
    counts = np.bincount(lay.curve_of, minlength=C) * F
    met = found.meets(targets)
    rel = (lambda x: x / diag) if diag else (lambda x: None)
    kg = 100.0 * found.rms * np.sqrt(F * V) / np.sqrt(space.spread) if space.spread > 0 else None
    S = len(knot_frames) - 1
    return FitReport(
        rms=found.rms, max=found.largest, rel_rms=rel(found.rms), rel_max=rel(found.largest), kg=kg,
        diagonal=diag, frames=F, vertices=V, curves=C, segments=S,
        segment_t=_normalised(plan.times)[knot_frames].tolist(), segment_frames=knot_frames.tolist(),
        per_frame_rms=np.sqrt(frame_sq / V).tolist(), per_frame_max=frame_max.tolist(),
        per_curve_rms=np.sqrt(curve_sq / np.maximum(counts, 1)).tolist(),
        per_curve_max=found.curve_max.tolist(),
        floor_rms=floor.rms, floor_rel_rms=rel(floor.rms), floor_max=floor.largest,
        float32_vs_float64_max=None, unrounded_rms=floor.rms, unrounded_max=floor.largest,
        targets={"rms": targets.rms, "max": targets.max}, target_met=met,
        floor_exceeds_target=not floor.meets(targets), adaptive_history=[], options=plan.options.to_dict(),
        curve_points=plan.report["curve_points"], curve_splits=plan.report["curve_splits"], dense_fit=True,
        segment_cap_reached=False, every_frame_a_knot=not met and S == F - 1,
        quantisation_tolerance=plan.tolerance, quantisation_knot_rms=None, quantisation_knot_cap=None,
        rate_control=[dict(t, window=w.index) for w in windows for t in w.trials],
        tolerances=plan.tol.to_dict(), knot_rank=knot_rank, time_models=time_models,
        windows=[{"frames": list(plan.window(w.index)), **w.quantisation,
                  "rms": float(np.sqrt(w.frame_sq.sum() / (len(w.frame_sq) * V))),
                  "trials": len(w.trials)} for w in windows],
        curve_frames=plan.report["curve_frames"],
        gram_floor_rel_rms=rel(float(np.sqrt(max(space.gram_floor, 0.0) / (F * V)))))


def fit_windowed(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
                 curves: CurveSet | None = None) -> ClipParts:
    """The clip of ``poses`` fitted in windows of frames, every step in this process (see the module
    docstring); its report has the keys of an in-memory fit's."""
    start = time.perf_counter()
    X = poses.vertices  # frames mapped from a file (pdeanim.poses.load_poses_npz_mapped) are read a window
    plan = plan_windows(poses, options, tol, sub_progress(progress, 0.0, 0.1), curves)  # at a time and their
    release_pages(X)  # pages dropped once it is done
    W = plan.n_windows
    progress(0.1, f"space fit ({plan.n_frames} frames in {W} windows)")

    def gram(i: int) -> GramPart:
        part = gram_window(plan, X[slice(*plan.window(i))], i)
        release_pages(X)
        return part

    space = join_space(plan, (gram(i) for i in range(W)))
    t_space = time.perf_counter()
    model = WindowModel(plan, space)
    codes = []
    for i in range(W):
        f0, f1 = plan.window(i)
        codes.append(encode_window(model, X[f0:f1], i, sub_progress(progress, 0.2 + 0.7 * i / W,
                                                                    0.2 + 0.7 * (i + 1) / W)))
        release_pages(X)
    t_codes = time.perf_counter()
    progress(0.92, "join")
    parts = join_clip(plan, space, codes)
    parts.report["timings_s"] = {"curves_and_space": t_space - start, "windows": t_codes - t_space,
                                 "join": time.perf_counter() - t_codes, "total": time.perf_counter() - start}
    progress(1.0, "done")
    return parts
