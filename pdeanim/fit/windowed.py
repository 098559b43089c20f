"""A fit of a long or large input in windows of frames, with a knot at every frame.

With a knot at every frame the knots of frame f depend on frame f alone (they are its projection on the
curves' space bases), and the stored clip at frame f is the rest pose plus the knot fields of knot f. So
everything but two small global choices runs one window of frames at a time: the space stage needs the Gram
matrix of every item summed over all frames (pass 1), each rate-control trial needs the stored clip's errors
summed over all frames (one pass per trial), and the clip's integer codes are written window by window. The
curves themselves are chosen on a subsample of the frames. Memory: a window of frames in float64, the
projected tracks of every frame in float32 and the clip's integer codes (4 bytes per knot coefficient),
never all frames in float64.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import container
from ..clipparts import FORMAT_VERSION, ClipParts, topology_id
from ..curveset import CurveSet
from ..model import quantise
from ..model.adaptive import Targets
from ..model.clipformat import TIME_SPLINE, TRIAL_LEVEL, decode_topology, topology_arrays
from ..model.families import SPACE_KINDS, space_basis
from ..model.fitcore import items_from_curves, vertex_slots
from ..model.metrics import bbox_diagonal
from ..model.parameterisation import curve_parameters
from ..model.spacefit import SpaceProjection, project_items, search_D
from ..model.spline import prefer_spline
from ..poses import Poses, make_poses
from ..progress import Progress, sub_progress
from .encode import Quantisation
from .options import FitOptions, FitTolerances
from .problem import u_grid
from .ratecontrol import Errors, first_quantisation, search_rounding
from .report import header_errors
from .spacestage import space_fit

CURVE_FRAMES = 128
"""Frames, evenly spaced, on which the curves of a windowed fit are chosen."""


def windowed_applies(poses: Poses, options: FitOptions, tol: FitTolerances) -> bool:
    """Whether a fit of ``poses`` runs in windows: inputs of more than tol.window_fit_values frame-vertex
    values, fitted with targets, displacement or absolute motion, chord parameters and an open clip (the
    other fits need every frame at once)."""
    return (poses.n_frames * poses.n_vertices > tol.window_fit_values and tol.dense_fit
            and not options.segments and not options.loop and options.motion != "rigid"
            and options.param_mode == "chord")


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

    def items(self, frames: np.ndarray) -> np.ndarray:
        """(w, K, N) float64 what the curves fit of frames (w, V, 3): displacement or positions."""
        values = frames if self.absolute else frames - self.rest.astype(np.float32)
        return items_from_curves(values, self.idx, self.mask)

    def u_per_vertex(self) -> np.ndarray:
        """(V, 3) curve parameter of every vertex and coordinate."""
        u_v = np.zeros((len(self.rest), 3))
        u_v[self.idx[self.mask]] = np.moveaxis(self.u, 1, 2)[self.mask]
        return u_v


def fit_windowed(poses: Poses, options: FitOptions, progress: Progress, tol: FitTolerances,
                 curves: CurveSet | None = None) -> ClipParts:
    """The clip of ``poses`` fitted in windows of frames (see the module docstring); its report has the keys
    of an in-memory fit's."""
    start = time.perf_counter()
    X = poses.vertices
    F, V = X.shape[:2]
    window = max(1, tol.window_values // max(V, 1))
    layout, sub_report = _layout(poses, options, curves, sub_progress(progress, 0.0, 0.1), tol)
    diag = bbox_diagonal(layout.rest)
    targets = options.targets(diag)
    progress(0.1, f"space fit ({F} frames in windows of {window})")
    proj, gram_floor = _space(layout, X, window)
    K = layout.mask.shape[0] * 3
    b = np.empty((K, F, 4), np.float32)  # every frame's projection on its item's basis
    floor, spread = _project(layout, proj, X, window, b)
    progress(0.3, "time models")
    t = _normalised(poses.times, F)
    spline = prefer_spline(b, t, tol.cubic_gain) if options.time_model == "auto" else (
        np.ptp(b, axis=1).any(axis=-1) if options.time_model == "spline" else np.zeros(K, bool))
    t_space = time.perf_counter()
    clip = _ClipModel(layout, proj, b, spline, poses, options)
    quant = first_quantisation(targets, floor.rms**2, tol)
    trials: list[dict] = []
    measure = sub_progress(progress, 0.35, 0.9)
    quant = search_rounding(targets, floor, quant, tol,
                            lambda q: clip.errors(q, X, window, measure, len(trials)), trials)
    progress(0.92, "encode")
    final = clip.errors(quant, X, window, None, 0, full=True)
    report = _report(final, floor, spread, targets, diag, options, layout, poses, trials, quant, sub_report,
                     tol)
    parts = clip.encode(quant, X, window, header_errors(report))
    t_time = time.perf_counter()
    report["timings_s"] = {"curves_and_space": t_space - start, "time_and_encode": t_time - t_space,
                           "report": time.perf_counter() - t_time, "total": time.perf_counter() - start}
    report["gram_floor_rel_rms"] = float(np.sqrt(gram_floor / (F * V))) / diag if diag else None
    header, arrays = container.unpack(parts.coefficients)
    report.update(format_version=header["format_version"], knot_rank=0,
                  time_models={"spline": int(spline.sum()), "pde": 0, "linear": int((~spline).sum())})
    parts.report = {**report, "sizes": parts.sizes(F, V)}
    progress(1.0, "done")
    return parts


def _layout(poses: Poses, options: FitOptions, curves: CurveSet | None, progress: Progress,
            tol: FitTolerances) -> tuple[Layout, dict]:
    """The curves (chosen on CURVE_FRAMES evenly spaced frames as an in-memory fit chooses them, unless given)
    and their per-vertex layout; and what the curve choice did (for the report)."""
    F = poses.n_frames
    picked = np.unique(np.round(np.linspace(0, F - 1, min(F, CURVE_FRAMES))).astype(np.int64))
    sub = make_poses(poses.vertices[picked], poses.faces, poses.times[picked])
    sf = space_fit(sub, options, curves, progress, tol)
    cs = sf.curves
    rest = np.asarray(poses.vertices[0], np.float64)
    idx, mask = cs.padded()
    u = curve_parameters(rest[idx], mask, "chord")
    grid = u_grid(mask.shape[1])
    u = np.rint(u / grid) * grid
    layout = Layout(cs, idx, mask, u, vertex_slots(idx, mask, len(rest)), cs.curve_of_vertex(len(rest))[0],
                    rest, options.motion == "absolute")
    return layout, {"curve_points": sf.curve_points, "curve_splits": sf.splits,
                    "curve_frames": int(len(picked))}


def _windows(F: int, window: int) -> Iterator[tuple[int, int]]:
    for f0 in range(0, F, window):
        yield f0, min(F, f0 + window)


def _space(layout: Layout, X: np.ndarray, window: int) -> tuple[SpaceProjection, float]:
    """Pass 1: each item's Gram matrix summed over every frame, then its space family and constant (as the
    in-memory space stage chooses them); and the floor's summed squared error the Gram matrices give."""
    K, N = layout.mask.shape[0] * 3, layout.mask.shape[1]
    gram = np.zeros((K, N, N))
    for f0, f1 in _windows(len(X), window):
        Yk = np.moveaxis(layout.items(X[f0:f1]), 0, 1)  # (K, w, N)
        gram += np.swapaxes(Yk, 1, 2) @ Yk
    u, mask = layout.u.reshape(K, N), np.repeat(layout.mask, 3, axis=0)
    kind, D, floor = search_D(u, mask, gram, check_cond=False)
    return project_items(u, mask, kind, D, fallback=True), float(floor.sum())


def _project(layout: Layout, proj: SpaceProjection, X: np.ndarray, window: int, b: np.ndarray
             ) -> tuple[Errors, float]:
    """Pass 2: every frame's projection into ``b`` (K, F, 4); the errors the space bases alone leave (the
    spatial floor: a knot at every frame fits every frame's projection exactly); and the summed squared
    distance of the vertices to their frame's centroid (the Karni-Gotsman error's denominator)."""
    F, V = X.shape[:2]
    C = layout.curves.n_curves
    sq, largest, curve_max, spread = 0.0, 0.0, np.zeros(C), 0.0
    for f0, f1 in _windows(F, window):
        frames = X[f0:f1].astype(np.float64)
        spread += float(((frames - frames.mean(axis=1, keepdims=True)) ** 2).sum())
        Yk = np.moveaxis(layout.items(X[f0:f1]), 0, 1)
        bw = Yk @ proj.U
        b[:, f0:f1] = bw
        d = _point_distances(Yk - bw @ np.swapaxes(proj.U, 1, 2), layout.slots)
        sq += float((d * d).sum())
        largest = max(largest, float(d.max(initial=0.0)))
        np.maximum.at(curve_max, layout.curve_of, d.max(axis=0, initial=0.0))
    return Errors(float(np.sqrt(sq / (F * V))), largest, curve_max), spread


def _point_distances(resid: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """(w, V) lengths of item residuals (K, w, N) at the vertices' slots."""
    K, w, N = resid.shape
    r = resid.reshape(K // 3, 3, w, N)
    sq = (r * r).sum(axis=1)  # (C, w, N)
    return np.sqrt(np.take(np.moveaxis(sq, 1, 0).reshape(w, -1), slots, axis=1))


def _normalised(times: np.ndarray, F: int) -> np.ndarray:
    times = np.asarray(times, np.float64)
    span = times[-1] - times[0] if F > 1 else 1.0
    return (times - times[0]) / span if span > 0 else np.zeros(F)


class _ClipModel:
    """A fit with a knot at every frame: its rounded clip's errors frame window by frame window, and its
    parts."""

    def __init__(self, layout: Layout, proj: SpaceProjection, b: np.ndarray, spline: np.ndarray,
                 poses: Poses, options: FitOptions):
        self.layout, self.proj, self.b, self.poses, self.options = layout, proj, b, poses, options
        C = layout.curves.n_curves
        self.C = C
        self.kind = proj.kind.reshape(C, 3).astype(np.uint8)
        self.D = proj.D.reshape(C, 3).astype(np.float32)
        self.spline = spline.reshape(C, 3)
        self.u_v = layout.u_per_vertex()
        cid = layout.curve_of
        basis = np.zeros((len(cid), 3, 4))
        u = self.u_v.astype(np.float32).astype(np.float64)
        Dv = self.D.astype(np.float64)[cid]
        kv = self.kind[cid]
        for i, name in enumerate(SPACE_KINDS):
            sel = kv == i
            if np.any(sel):
                basis[sel] = space_basis(u[sel][:, None], Dv[sel], name)[:, 0, :]
        self.basis = basis  # (V, 3, 4): the evaluator's space basis
        N = layout.mask.shape[1]
        padded = np.zeros((C * N, 3, 4))
        padded[layout.slots] = basis
        self.padded_basis = np.ascontiguousarray(padded.reshape(C, N, 3, 4))  # the same on the padded curves
        # every frame is a knot: the linear pair's bound is 1, the spline items' that of the in-memory writer
        bound = np.where(self.spline, quantise.CUBIC_PAIR_MAX, 1.0)
        self.weight, self.reach = quantise.item_sensitivity(cid, basis, C, 1.0, bound)
        self.largest_knot = np.zeros((C, 3))
        for f0, f1 in _windows(b.shape[1], max(1, (1 << 22) // max(b.shape[0] * 4, 1))):
            np.maximum(self.largest_knot, np.abs(self._knots(f0, f1)).max(axis=(0, 3)), out=self.largest_knot)
        self._topologies: dict[float | None, tuple[bytes, np.ndarray]] = {}

    def _knots(self, f0: int, f1: int) -> np.ndarray:
        """(w, C, 3, 4) float64 knots of frames f0..f1 (balanced space coefficients of their projection)."""
        bw = self.b[:, f0:f1].astype(np.float64)  # (K, w, 4)
        k = np.einsum("kab,kwb->kwa", self.proj.to_coef, bw)
        return np.moveaxis(k.reshape(self.C, 3, f1 - f0, 4), 2, 0)

    def steps(self, quant: Quantisation) -> np.ndarray:
        """(C, 3) float32 knot steps of a rounding (quantise.knot_steps_rms with the cubic weights at the
        knots: every frame is a knot, where the stored value is the knot's)."""
        big = self.largest_knot[None, :, :, None]
        if quant.knot_rms is not None:
            steps = quantise.budget_steps(self.weight, self.reach, quant.knot_rms, quant.knot_cap, big)
        else:
            steps = quantise.refined_steps(2.0 * quant.tolerance / np.maximum(self.reach, 1e-30),
                                           np.zeros((self.C, 3)), big)
        if quant.refine is not None:
            steps = quantise.refined_steps(steps, quant.refine, big)
        return steps

    def _fields(self, knots: np.ndarray) -> np.ndarray:
        """(w, V, 3) float32 knot fields at the vertices of knots (w, C, 3, 4), computed on the padded curves
        (no (w, V, 3, 4) temporary) in float64 and rounded as the evaluator rounds its fields."""
        on_curves = np.einsum("cnwk,fcwk->fcnw", self.padded_basis, knots)  # (w, C, N, 3)
        w = len(knots)
        return np.take(on_curves.reshape(w, -1, 3), self.layout.slots, axis=1).astype(np.float32)

    def topology(self, quant: Quantisation) -> tuple[bytes, np.ndarray]:
        """(topology part bytes, base (V, 3) float32 the stored clip adds its fields to)."""
        if quant.tolerance not in self._topologies:
            lay = self.layout
            header, arrays = topology_arrays(lay.curves, self.u_v, self.poses.faces, lay.rest,
                                             self.options.param_mode, quant.tolerance)
            topo = decode_topology(header, arrays)
            packed = container.pack(header, arrays, {n: container.SMALLEST for n in arrays})
            base = np.zeros_like(topo.rest) if lay.absolute else np.asarray(topo.rest, np.float32)
            self._topologies = {quant.tolerance: (packed, base)}
        return self._topologies[quant.tolerance]

    def errors(self, quant: Quantisation, X: np.ndarray, window: int, progress: Progress | None, trial: int,
               full: bool = False) -> Errors | dict[str, Any]:
        """The stored clip's errors at every frame (one pass); with ``full`` also per frame and per curve
        sums (for the report)."""
        if progress is not None:
            progress(min(trial / 10.0, 1.0), f"rounding trial {trial + 1}")
        steps = self.steps(quant).astype(np.float64)
        _, base = self.topology(quant)
        F, V = X.shape[:2]
        cid = self.layout.curve_of
        sq, largest, curve_max = 0.0, 0.0, np.zeros(self.C)
        frame_sq, frame_max, curve_sq = np.zeros(F), np.zeros(F), np.zeros(self.C)
        for f0, f1 in _windows(F, window):
            codes = np.rint(self._knots(f0, f1) / steps[None, :, :, None])
            stored_knots = (codes * steps[None, :, :, None]).astype(np.float32).astype(np.float64)
            fields = self._fields(stored_knots)
            d = np.linalg.norm((fields + base).astype(np.float64) - X[f0:f1], axis=-1)  # (w, V)
            dd = d * d
            sq += float(dd.sum())
            largest = max(largest, float(d.max(initial=0.0)))
            np.maximum.at(curve_max, cid, d.max(axis=0, initial=0.0))
            if full:
                frame_sq[f0:f1], frame_max[f0:f1] = dd.sum(axis=1), d.max(axis=1, initial=0.0)
                curve_sq += np.bincount(cid, dd.sum(axis=0), minlength=self.C)
        found = Errors(float(np.sqrt(sq / (F * V))), largest, curve_max)
        if not full:
            return found
        return {"errors": found, "frame_sq": frame_sq, "frame_max": frame_max, "curve_sq": curve_sq}

    def encode(self, quant: Quantisation, X: np.ndarray, window: int, errors: dict) -> ClipParts:
        """Both parts of the stored clip (the knots as plain tracks), the codes written window by window;
        ``errors``: the header's error summary."""
        topology, _ = self.topology(quant)
        steps = self.steps(quant)
        F = X.shape[0]
        codes = np.empty((self.C, 3, 4, F), np.int32)  # the tracks' layout: time last
        for f0, f1 in _windows(F, window):
            q = np.rint(self._knots(f0, f1) / steps.astype(np.float64)[None, :, :, None])
            if np.abs(q).max(initial=0) > quantise.MAX_CODE:
                raise ValueError("knot codes out of range")  # the steps keep them in range
            codes[..., f0:f1] = np.moveaxis(q, 0, -1)
        tracks, order = _tracks(codes)
        times = np.asarray(self.poses.times, np.float64)
        S = F - 1
        header = {"errors": errors, "part": "coefficients", "kind": "dynamic-pde",
                  "format_version": FORMAT_VERSION, "topology_id": topology_id(topology),
                  "motion": self.options.motion, "looping": False,
                  "n_segments": int(S), "n_curves": int(self.C), "n_frames": int(F),
                  "knot_differences": order, "knot_rank": 0}
        arrays = {
            "segment_t": _normalised(times, F),
            "frame_times": times,
            "space_kind": self.kind,
            "time_model": np.where(self.spline, TIME_SPLINE, 0).astype(np.uint8),
            "m": np.zeros((S, self.C, 3), np.float32),
            "D": self.D,
            "knot_step": steps,
            "knots": tracks,
        }
        coefficients = container.pack(header, arrays, {n: container.SMALLEST for n in arrays})
        return ClipParts(topology, coefficients)


def _tracks(codes: np.ndarray) -> tuple[np.ndarray, int]:
    """(uint32 tracks (C, 3, 4, F), order): zigzag differences of the codes along time, of order 1 or 2,
    whichever compresses smaller at the trial level (the in-memory encoder's rule)."""
    import zstandard

    size = zstandard.ZstdCompressor(level=TRIAL_LEVEL).compress
    first = _zigzag(np.diff(codes, axis=-1, prepend=0))
    second = _zigzag(np.diff(np.diff(codes, axis=-1, prepend=0), axis=-1, prepend=0))
    return (first, 1) if len(size(first)) <= len(size(second)) else (second, 2)


def _zigzag(d: np.ndarray) -> np.ndarray:
    """uint32 zigzag codes of int32 differences (the int32 range is checked: codes stay within MAX_CODE)."""
    d = d.astype(np.int32)
    return ((d.astype(np.uint32) << np.uint32(1)) ^ (d >> 31).astype(np.uint32)).astype(np.uint32)


def _report(final: dict, floor: Errors, spread: float, targets: Targets, diag: float, options: FitOptions,
            layout: Layout, poses: Poses, trials: list[dict], quant: Quantisation, sub_report: dict,
            tol: FitTolerances) -> dict[str, Any]:
    """The fit report of a windowed fit (the keys of an in-memory fit's report)."""
    found: Errors = final["errors"]
    F, V = poses.n_frames, poses.n_vertices
    counts = np.bincount(layout.curve_of, minlength=layout.curves.n_curves) * F
    met = found.meets(targets)
    rel = (lambda x: x / diag) if diag else (lambda x: None)
    return {
        "rms": found.rms, "max": found.largest, "rel_rms": rel(found.rms), "rel_max": rel(found.largest),
        "kg": 100.0 * found.rms * np.sqrt(F * V) / np.sqrt(spread) if spread > 0 else None, "diagonal": diag,
        "frames": F, "vertices": V, "curves": layout.curves.n_curves, "segments": F - 1,
        "segment_t": _normalised(poses.times, F).tolist(), "segment_frames": list(range(F)),
        "per_frame_rms": np.sqrt(final["frame_sq"] / V).tolist(),
        "per_frame_max": final["frame_max"].tolist(),
        "per_curve_rms": np.sqrt(final["curve_sq"] / np.maximum(counts, 1)).tolist(),
        "per_curve_max": found.curve_max.tolist(),
        "floor_rms": floor.rms, "floor_rel_rms": rel(floor.rms), "floor_max": floor.largest,
        "float32_vs_float64_max": None, "unrounded_rms": floor.rms, "unrounded_max": floor.largest,
        "targets": {"rms": targets.rms, "max": targets.max}, "target_met": met,
        "floor_exceeds_target": not floor.meets(targets), "adaptive_history": [],
        "options": options.to_dict(), **sub_report, "dense_fit": True, "windowed": True,
        "segment_cap_reached": False, "every_frame_a_knot": not met,
        "quantisation_tolerance": quant.tolerance, "quantisation_knot_rms": quant.knot_rms,
        "quantisation_knot_cap": quant.knot_cap, "rate_control": trials, "tolerances": tol.to_dict(),
    }
