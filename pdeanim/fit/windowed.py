"""A fit of a long or large input in windows of frames, with a knot at every frame, as steps that any process
may run: the windows are independent but for two joins.

With a knot at every frame the knots of frame f depend on frame f alone (its projection on the curves' space
bases), and the stored clip at frame f is the rest pose plus the knot fields of knot f. So the fit runs as

1. :func:`plan_windows`: the curves (chosen on a subsample of the frames), the rest pose's rounding and the
   window bounds;
2. :func:`gram_window` per window, then :func:`join_space`: the space family and constant of every item from
   its Gram matrix summed over all frames;
3. :func:`encode_window` per window: the window's knots, their rate control (its own knot steps, so that
   every window meets the targets alone) and integer codes;
4. :func:`join_clip`: the time models, the knot tracks and both parts of the clip.

Every step's result has ``to_bytes``/``from_bytes`` so that a job queue can hand windows to other workers
(service: one task per window). Memory of a step: one window of frames in float64, never all frames.
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
from ..model.clipformat import TIME_SPLINE, decode_topology, topology_arrays
from ..model.coefwriter import CoefficientFields, KnotCodes, write_coefficients
from ..model.families import SPACE_KINDS, space_basis
from ..model.fitcore import items_from_curves, vertex_slots
from ..model.metrics import bbox_diagonal
from ..model.parameterisation import curve_parameters
from ..model.spacefit import SpaceProjection, project_items, search_D
from ..model.spline import spline_evidence
from ..poses import Poses, make_poses
from ..progress import Progress, sub_progress
from .encode import Quantisation
from .options import FitOptions, FitTolerances
from .problem import u_grid
from .ratecontrol import Errors, first_quantisation, search_rounding
from .report import FitReport
from .spacestage import space_fit

CURVE_FRAMES = 128
"""Frames, evenly spaced, on which the curves of a windowed fit are chosen, at most ..."""
CURVE_VALUES = 1 << 20
"""... and at most this many frame-vertex values (an in-memory space fit takes a few hundred bytes each), but
at least MIN_WINDOW_FRAMES frames."""
MIN_WINDOW_FRAMES = 8
"""Frames per window at least (the time-model evidence needs a few frames on either side)."""


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
                      "times": self.times, "topology": np.frombuffer(self.topology, np.uint8)})

    @classmethod
    def from_bytes(cls, blob: bytes) -> WindowPlan:
        h, a = _unpack("plan", blob)
        options = FitOptions.from_dict(h["options"])
        curves = CurveSet(a["order"].astype(np.int32), a["offsets"].astype(np.int32))
        return cls(options, FitTolerances(**h["tolerances"]),
                   Layout.of(curves, a["rest"], options.motion == "absolute"), a["bounds"].astype(np.int64),
                   a["times"], a["topology"].tobytes(), h["tolerance"], h["diagonal"], h["report"])


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
    return WindowPlan(options, tol, layout, window_bounds(F, V, tol), np.asarray(poses.times, np.float64),
                      topology, tolerance, diagonal, report)


@dataclass
class GramPart:
    """One window's share of the space stage: every item's Gram matrix (K, N, N) summed over the window's
    frames, and the window's summed squared distance of the vertices to their frame's centroid."""

    gram: np.ndarray
    spread: float

    def to_bytes(self) -> bytes:
        return _pack("gram", {"spread": self.spread}, {"gram": self.gram})

    @classmethod
    def from_bytes(cls, blob: bytes) -> GramPart:
        h, a = _unpack("gram", blob)
        return cls(a["gram"], float(h["spread"]))


def gram_window(plan: WindowPlan, frames: np.ndarray) -> GramPart:
    """Step 2, per window: the Gram matrices and spread of ``frames`` (w, V, 3)."""
    Yk = plan.layout.item_rows(frames)  # (K, w, N)
    f = np.asarray(frames, np.float64)
    spread = float(((f - f.mean(axis=1, keepdims=True)) ** 2).sum())
    return GramPart(np.swapaxes(Yk, 1, 2) @ Yk, spread)


@dataclass
class SpaceModel:
    """The space family (K,) and constant D (K,) of every item, and what the whole sequence's Gram matrices
    and spread gave (the floor's summed squared error, the Karni-Gotsman denominator)."""

    kind: np.ndarray
    D: np.ndarray
    gram_floor: float
    spread: float

    def projection(self, plan: WindowPlan) -> SpaceProjection:
        """The items' orthonormal space bases (the same, bit for bit, in every process)."""
        K, N = plan.layout.n_items, plan.layout.mask.shape[1]
        return project_items(plan.layout.u.reshape(K, N), np.repeat(plan.layout.mask, 3, axis=0),
                             self.kind, self.D, fallback=True)

    def to_bytes(self) -> bytes:
        return _pack("space", {"gram_floor": self.gram_floor, "spread": self.spread},
                     {"kind": self.kind.astype(np.uint8), "D": self.D.astype(np.float64)})

    @classmethod
    def from_bytes(cls, blob: bytes) -> SpaceModel:
        h, a = _unpack("space", blob)
        return cls(a["kind"].astype(np.int64), a["D"], float(h["gram_floor"]), float(h["spread"]))


def join_space(plan: WindowPlan, parts: Iterable[GramPart]) -> SpaceModel:
    """Join 1: each item's space family and constant, as the in-memory space stage chooses them, from the Gram
    matrices summed over every window."""
    lay = plan.layout
    K, N = lay.n_items, lay.mask.shape[1]
    gram, spread = np.zeros((K, N, N)), 0.0
    for part in parts:
        gram += part.gram
        spread += part.spread
    u, mask = lay.u.reshape(K, N), np.repeat(lay.mask, 3, axis=0)
    kind, D, floor = search_D(u, mask, gram, check_cond=False)
    proj = project_items(u, mask, kind, D, fallback=True)
    return SpaceModel(np.asarray(proj.kind, np.int64), np.asarray(proj.D, np.float64), float(floor.sum()),
                      spread)


@dataclass
class WindowCodes:
    """One window's share of the clip: integer knot codes (C, 3, 4, w) on its own knot steps (C, 3), the
    time-model evidence of its tracks, its errors (stored clip and unrounded floor), rate-control trials."""

    index: int
    codes: np.ndarray
    steps: np.ndarray
    e_lin: np.ndarray  # (K,)
    e_cub: np.ndarray  # (K,)
    b_min: np.ndarray  # (K, 4) float32
    b_max: np.ndarray  # (K, 4) float32
    frame_sq: np.ndarray  # (w,)
    frame_max: np.ndarray  # (w,)
    curve_sq: np.ndarray  # (C,)
    curve_max: np.ndarray  # (C,)
    floor_sq: float
    floor_max: float
    trials: list[dict]
    quantisation: dict[str, Any]

    _ARRAYS = ("codes", "steps", "e_lin", "e_cub", "b_min", "b_max", "frame_sq", "frame_max", "curve_sq",
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
    """What the encoding of every window shares: the space bases and, per vertex, the evaluator's space basis
    (built once per process from the plan and the space model)."""

    def __init__(self, plan: WindowPlan, space: SpaceModel):
        self.plan, self.space = plan, space
        lay = plan.layout
        self.proj = space.projection(plan)
        C = lay.curves.n_curves
        self.C = C
        self.kind = self.proj.kind.reshape(C, 3).astype(np.uint8)
        self.D = self.proj.D.reshape(C, 3).astype(np.float32)
        cid = lay.curve_of
        u = lay.u_per_vertex().astype(np.float32).astype(np.float64)
        basis = np.zeros((len(cid), 3, 4))
        Dv, kv = self.D.astype(np.float64)[cid], self.kind[cid]
        for i, name in enumerate(SPACE_KINDS):
            sel = kv == i
            if np.any(sel):
                basis[sel] = space_basis(u[sel][:, None], Dv[sel], name)[:, 0, :]
        self.basis = basis  # (V, 3, 4): the evaluator's space basis
        N = lay.mask.shape[1]
        padded = np.zeros((C * N, 3, 4))
        padded[lay.slots] = basis
        # (C * 3, N, 4): each item's basis on its padded curve, so that fields are one batched product
        by_item = np.moveaxis(padded.reshape(C, N, 3, 4), 2, 1)  # (C, 3, N, 4)
        self.item_basis = np.ascontiguousarray(by_item).reshape(-1, N, 4)
        c, n = np.divmod(lay.slots, N)
        self.rows = ((c * 3)[:, None] + np.arange(3)[None, :]) * N + n[:, None]  # (V, 3) rows of the fields
        self.base = plan.base()

    def knots(self, b: np.ndarray) -> np.ndarray:
        """(w, C, 3, 4) float64 knots (balanced space coefficients) of projections b (K, w, 4)."""
        k = np.einsum("kab,kwb->kwa", self.proj.to_coef, np.asarray(b, np.float64))
        return np.moveaxis(k.reshape(self.C, 3, b.shape[1], 4), 2, 0)

    def fields(self, knots: np.ndarray) -> np.ndarray:
        """(V, 3, w) float32 knot fields at the vertices of knots (C * 3, 4, w), computed on the padded curves
        (no (V, 3, 4, w) temporary) in float64 and rounded as the evaluator rounds its fields; frames last, so
        that gathering a vertex copies a contiguous run."""
        on_curves = np.matmul(self.item_basis, knots)  # (C * 3, N, w)
        w = knots.shape[-1]
        return np.take(on_curves.reshape(-1, w), self.rows, axis=0).astype(np.float32)


def encode_window(model: WindowModel, frames: np.ndarray, index: int, progress: Progress | None = None
                  ) -> WindowCodes:
    """Step 3, per window: the knots of ``frames`` (w, V, 3; window ``index``), the coarsest knot steps
    (rate control as in an in-memory fit, on this window's frames) with which the window meets the targets,
    and their codes."""
    plan, lay = model.plan, model.plan.layout
    f0, f1 = plan.window(index)
    if len(frames) != f1 - f0:
        raise InputError(f"window {index} has {f1 - f0} frames, got {len(frames)}")
    Yk = lay.item_rows(frames)
    b = Yk @ model.proj.U  # (K, w, 4)
    d = _point_distances(Yk - b @ np.swapaxes(model.proj.U, 1, 2), lay.slots)
    del Yk
    C = model.C
    floor = Errors.of(d, lay.curve_of, C)
    t = _normalised(plan.times)[f0:f1]
    e_lin, e_cub = spline_evidence(b, t)
    spline = (e_cub < plan.tol.cubic_gain * e_lin) & (e_lin > 0)
    knots = model.knots(b)  # (w, C, 3, 4)
    largest = np.abs(knots).max(axis=(0, 3))[None, :, :, None]
    knots = np.ascontiguousarray(np.moveaxis(knots, 0, -1))  # (C, 3, 4, w): the tracks' layout
    # every frame is a knot: the linear pair's bound is 1, the spline items' that of the in-memory writer
    bound = np.where(spline.reshape(C, 3), quantise.CUBIC_PAIR_MAX, 1.0)
    weight, reach = quantise.item_sensitivity(lay.curve_of, model.basis, C, 1.0, bound)
    target_t = np.ascontiguousarray(np.moveaxis(np.asarray(frames, np.float64), 0, -1))  # (V, 3, w)
    base = model.base[:, :, None]

    def steps_of(quant: Quantisation) -> np.ndarray:
        if quant.knot_rms is not None:
            steps = quantise.budget_steps(weight, reach, quant.knot_rms, quant.knot_cap, largest)
        else:
            steps = quantise.refined_steps(2.0 * quant.tolerance / np.maximum(reach, 1e-30), np.zeros((C, 3)),
                                           largest)
        if quant.refine is not None:
            steps = quantise.refined_steps(steps, quant.refine, largest)
        return steps

    def distances(quant: Quantisation) -> tuple[np.ndarray, np.ndarray]:
        """(V, w) distances of the stored clip to the frames, and the codes (C, 3, 4, w)."""
        s64 = steps_of(quant).astype(np.float64)[:, :, None, None]
        codes = np.rint(knots / s64)
        stored = (codes * s64).astype(np.float32).astype(np.float64).reshape(C * 3, 4, -1)
        diff = (model.fields(stored) + base).astype(np.float64)
        diff -= target_t
        return np.sqrt(np.einsum("vcw,vcw->vw", diff, diff)), codes

    trials: list[dict] = []
    targets = plan.targets
    quant = first_quantisation(targets, floor.rms**2, plan.tol)
    quant.tolerance = plan.tolerance

    def measure(q: Quantisation) -> Errors:
        if progress is not None:
            progress(min(len(trials) / 10.0, 1.0), f"window {index + 1}: rounding trial {len(trials) + 1}")
        return Errors.of(distances(q)[0].T, lay.curve_of, C)

    tol = replace(plan.tol, quant_fill=plan.tol.window_quant_fill)
    quant = search_rounding(targets, floor, quant, tol, measure, trials)
    dist, codes = distances(quant)
    if np.abs(codes).max(initial=0) > quantise.MAX_CODE:
        raise ValueError("knot codes out of range")  # the steps keep them in range
    dd = dist * dist
    return WindowCodes(
        index, codes.astype(np.int32), steps_of(quant), e_lin, e_cub, b.min(axis=1).astype(np.float32),
        b.max(axis=1).astype(np.float32), dd.sum(axis=0), dist.max(axis=0, initial=0.0),
        np.bincount(lay.curve_of, dd.sum(axis=1), minlength=C), Errors.of(dist.T, lay.curve_of, C).curve_max,
        float((d * d).sum()), float(d.max(initial=0.0)), trials,
        {"tolerance": quant.tolerance, "knot_rms": quant.knot_rms, "knot_cap": quant.knot_cap})


def _point_distances(resid: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """(w, V) lengths of item residuals (K, w, N) at the vertices' slots."""
    K, w, N = resid.shape
    r = resid.reshape(K // 3, 3, w, N)
    sq = (r * r).sum(axis=1)  # (C, w, N)
    return np.sqrt(np.take(np.moveaxis(sq, 1, 0).reshape(w, -1), slots, axis=1))


def _normalised(times: np.ndarray) -> np.ndarray:
    times = np.asarray(times, np.float64)
    span = times[-1] - times[0] if len(times) > 1 else 1.0
    return (times - times[0]) / span if span > 0 else np.zeros(len(times))


def join_clip(plan: WindowPlan, space: SpaceModel, windows: Sequence[WindowCodes],
              timings: dict[str, float] | None = None) -> ClipParts:
    """Join 2: the clip of every window's codes: the time model of every item from the whole sequence's
    evidence, the knot tracks, both parts and the fit report. Each window's codes are released (set to None)
    once copied into the clip's."""
    W = plan.n_windows
    windows = sorted(windows, key=lambda w: w.index)
    if [w.index for w in windows] != list(range(W)):
        raise InputError(f"a windowed fit joins all {W} windows, got {[w.index for w in windows]}")
    lay, options = plan.layout, plan.options
    C, F = lay.curves.n_curves, plan.n_frames
    if options.time_model == "auto":
        e_lin = np.sum([w.e_lin for w in windows], axis=0)
        e_cub = np.sum([w.e_cub for w in windows], axis=0)
        spline = (e_cub < plan.tol.cubic_gain * e_lin) & (e_lin > 0)
    elif options.time_model == "spline":
        lo = np.min([w.b_min for w in windows], axis=0)
        hi = np.max([w.b_max for w in windows], axis=0)
        spline = (hi > lo).any(axis=-1)
    else:
        spline = np.zeros(lay.n_items, bool)
    codes = np.empty((C, 3, 4, F), np.int32)
    for w in windows:  # each window's codes are released once copied
        f0, f1 = plan.window(w.index)
        codes[..., f0:f1], w.codes = w.codes, None
    order = quantise.difference_order(codes)
    tracks = quantise.track_codes(codes, order, in_place=True)
    S = F - 1
    steps = windows[0].steps if W == 1 else np.stack([w.steps for w in windows])
    report = _report(plan, space, windows, spline)
    time_model = np.where(spline.reshape(C, 3), TIME_SPLINE, 0)
    fields = CoefficientFields(_normalised(plan.times), plan.times, space.kind.reshape(C, 3), time_model,
                               np.zeros((S, C, 3), np.float32), space.D.reshape(C, 3), options.motion, False)
    knots = KnotCodes(steps, tracks, order, windows=plan.bounds if W > 1 else None)
    header, arrays = write_coefficients(fields, knots, topology_id(plan.topology),
                                        {"errors": report.header_errors()})
    coefficients = container.pack(header, arrays, {n: container.SMALLEST for n in arrays})
    parts = ClipParts(plan.topology, coefficients)
    report.timings_s = timings or None
    parts.report = {**report.to_dict(), "sizes": parts.sizes(F, lay.rest.shape[0])}
    return parts


def _report(plan: WindowPlan, space: SpaceModel, windows: Sequence[WindowCodes], spline: np.ndarray
            ) -> FitReport:
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
    K = lay.n_items
    return FitReport(
        rms=found.rms, max=found.largest, rel_rms=rel(found.rms), rel_max=rel(found.largest), kg=kg,
        diagonal=diag, frames=F, vertices=V, curves=C, segments=F - 1,
        segment_t=_normalised(plan.times).tolist(), segment_frames=list(range(F)),
        per_frame_rms=np.sqrt(frame_sq / V).tolist(), per_frame_max=frame_max.tolist(),
        per_curve_rms=np.sqrt(curve_sq / np.maximum(counts, 1)).tolist(),
        per_curve_max=found.curve_max.tolist(),
        floor_rms=floor.rms, floor_rel_rms=rel(floor.rms), floor_max=floor.largest,
        float32_vs_float64_max=None, unrounded_rms=floor.rms, unrounded_max=floor.largest,
        targets={"rms": targets.rms, "max": targets.max}, target_met=met,
        floor_exceeds_target=not floor.meets(targets), adaptive_history=[], options=plan.options.to_dict(),
        curve_points=plan.report["curve_points"], curve_splits=plan.report["curve_splits"], dense_fit=True,
        segment_cap_reached=False, every_frame_a_knot=not met, quantisation_tolerance=plan.tolerance,
        quantisation_knot_rms=None, quantisation_knot_cap=None,
        rate_control=[dict(t, window=w.index) for w in windows for t in w.trials],
        tolerances=plan.tol.to_dict(), knot_rank=0,
        time_models={"spline": int(spline.sum()), "pde": 0, "linear": int(K - spline.sum())},
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
    X = poses.vertices
    plan = plan_windows(poses, options, tol, sub_progress(progress, 0.0, 0.1), curves)
    W = plan.n_windows
    progress(0.1, f"space fit ({plan.n_frames} frames in {W} windows)")
    space = join_space(plan, (gram_window(plan, X[f0:f1]) for f0, f1 in map(plan.window, range(W))))
    t_space = time.perf_counter()
    model = WindowModel(plan, space)
    codes = []
    for i in range(W):
        f0, f1 = plan.window(i)
        codes.append(encode_window(model, X[f0:f1], i, sub_progress(progress, 0.2 + 0.7 * i / W,
                                                                    0.2 + 0.7 * (i + 1) / W)))
    t_codes = time.perf_counter()
    progress(0.92, "join")
    parts = join_clip(plan, space, codes)
    parts.report["timings_s"] = {"curves_and_space": t_space - start, "windows": t_codes - t_space,
                                 "join": time.perf_counter() - t_codes, "total": time.perf_counter() - start}
    progress(1.0, "done")
    return parts
