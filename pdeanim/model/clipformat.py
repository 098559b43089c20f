"""The "dynamic-pde" clip format 1.0 (docs/format.md §3): a topology part and a coefficients part, both
pdeanim containers, every large array an integer code on an error-bounded step (:mod:`pdeanim.model.quantise`)
stored as zigzag differences and compressed with zstd.

Topology part (``part: "topology"``, ``model: "dynamic-pde"``; once per mesh + curve layout + rest pose)::

    curve_lengths (C,)      uint32  vertices of each curve
    order         (V,)      uint32  zigzag differences of the vertex indices, curve by curve
    u             (V, 1|3)  uint32  curve parameter per vertex in curve order, zigzag differences, x u_step
    faces         (T, 3)    uint32  triangles in curve-rank space (quantise.encode_faces)
    rest          (V, 3)    uint32  first-frame positions in curve order, zigzag differences, x rest_step

Coefficients part (``part: "coefficients"``, ``kind: "dynamic-pde"``, ``topology_id`` = SHA-256 of the
topology bytes). Features are fields of the one layout, present or absent, never versions::

    segment_t    (S+1,)          float64  segment boundaries in normalised clip time t in [0, 1]
    frame_times  (F,)            float64  seconds of the source frames
    space_kind   (C, 3)          uint8    space family D0 / D1 of each curve and coordinate
    time_model   (C, 3)          uint8    0: the paper's time pair per segment (signed m), 1: natural spline
    m            (S, C, 3)       float32  signed time constant (> 0 exp, < 0 trig, 0 linear; 0 for splines)
    D            (C, 3)          float32  space constant
    knot_step    (C, 3)          float32  power-of-two step of the knots
    knots        (C, 3, 4, S+1)  uint32   knot time tracks (zigzag differences of order knot_differences)
    knot_weights (r, C, 3, 4)    uint32   with knot_rank r > 0: weights on r shared time tracks ...
    knot_basis   (r, S+1)        float32  ... and the tracks; ``knots`` then holds the residual
    rigid_*      only for motion "rigid" (see pdeanim.model.rigid)

The 8 coefficients of segment s, curve c, coordinate w are its two knots (2, 4) in the balanced bases of
:mod:`pdeanim.model.families`; :func:`pdeanim.model.families.paper_coefficients` converts them to the
paper's c1..c8.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import container
from ..clipparts import FORMAT_VERSION, VALUE_LIMIT, topology_id
from ..curveset import CurveSet
from ..errors import ClipFormatError
from . import knotbasis, quantise
from .bonelayer import EncodedBones, bones_header_arrays, decode_bones, has_bones
from .coefwriter import CoefficientFields, KnotCodes, frame_segment_t, write_coefficients
from .spline import spline_weight_bound

BASIS_MARGIN = 0.9
"""The knots go on a shared basis only where that encoding is below this share of the plain tracks' bytes at
the trial level: level 19 compresses plain tracks relatively better (horse-collapse, dense fit at 3e-3:
rank 18 looked smaller at level 3, 161,200 B against 143,992 B at level 19)."""
TRIAL_LEVEL = quantise.TRIAL_LEVEL
SHARED_KEY = "knot_shared"
"""Header key of a windowed fit's window trial encoding whose knots are on the clip's shared weights (never in
a written clip: the join stores the weights once)."""

MOTIONS = ("displacement", "absolute", "rigid")
TIME_PDE, TIME_SPLINE = 0, 1
"""Time models of an item (``time_model``): the paper's time pair with a constant per segment (Eq. 5-8), or
the natural cubic spline through the item's knots (docs/format.md §3.5)."""
DEFAULT_TOLERANCE = 1e-5
"""Quantisation tolerance relative to the rest pose's bounding-box diagonal, when the caller gives none (a fit
with error targets passes a share of its target)."""


@dataclass
class TopologyData:
    """Decoded topology part (see the module docstring for shapes)."""

    curves: CurveSet
    u: np.ndarray
    faces: np.ndarray
    rest: np.ndarray
    param_mode: str


@dataclass
class CoefficientData:
    """Decoded coefficients part: family (S, C, 3) 0..3 and m (S, C, 3) >= 0 as in the paper (Eq. 5-8),
    knots (S+1, C, 3, 4) float32, time_model (C, 3) uint8 (TIME_PDE or TIME_SPLINE)."""

    segment_t: np.ndarray
    frame_times: np.ndarray
    family: np.ndarray
    m: np.ndarray
    D: np.ndarray
    knots: np.ndarray
    motion: str
    looping: bool
    header: dict[str, Any]
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # "rigid_*" arrays of motion "rigid"
    time_model: np.ndarray | None = None  # (C, 3) uint8; None: every item TIME_PDE
    bones: EncodedBones | None = None  # format 1.1 bone layer (§3.9); the curves are then the residual
    shared: knotbasis.SharedWeights | None = None  # weights a windowed fit's windows share (writer only)

    def spline_items(self) -> np.ndarray:
        """(C, 3) bool: the items on the natural spline."""
        if self.time_model is None:
            return np.zeros(self.D.shape, bool)
        return np.asarray(self.time_model) == TIME_SPLINE


def encode_topology(curves: CurveSet, u: np.ndarray, faces: np.ndarray, rest: np.ndarray,
                    param_mode: str, tolerance: float | None = None, level: int = container.ZSTD_LEVEL
                    ) -> bytes:
    """Topology part bytes from curves, u (V, 3), faces (T, 3), rest (V, 3): rest rounded to a step whose
    error is at most ``tolerance`` (default: DEFAULT_TOLERANCE of the diagonal), compressed at zstd ``level``
    (a trial encoding may use a fast one)."""
    header, arrays = topology_arrays(curves, u, faces, rest, param_mode, tolerance)
    return container.pack(header, arrays, {name: container.SMALLEST for name in arrays}, level)


def topology_arrays(curves: CurveSet, u: np.ndarray, faces: np.ndarray, rest: np.ndarray, param_mode: str,
                    tolerance: float | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of the topology part before packing (:func:`decode_topology` reads them as they
    are: what a reader of the packed part decodes, without compressing anything)."""
    header = {"part": "topology", "model": "dynamic-pde", "format_version": FORMAT_VERSION,
              "n_vertices": int(len(rest)), "n_curves": curves.n_curves, "param_mode": param_mode}
    u = np.asarray(u, np.float32)
    if u.ndim == 2 and u.shape[1] == 3 and np.array_equal(u[:, :1], u[:, 1:2]) and np.array_equal(
            u[:, :1], u[:, 2:]):
        u = u[:, :1]
    rest = np.asarray(rest, np.float32)
    tol = tolerance if tolerance is not None else DEFAULT_TOLERANCE * _diagonal(rest)
    origin, step = quantise.rest_origin_step(rest, tol)
    order = np.asarray(curves.order, np.int64)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    step_u = quantise.u_step(u)
    header.update({"rest_origin": [float(x) for x in origin], "rest_step": step, "u_step": step_u})
    return header, {
        "curve_lengths": np.diff(np.asarray(curves.offsets, np.int64)).astype(np.uint32),
        "order": quantise.zigzag_deltas(order),
        "u": quantise.zigzag_deltas(np.rint(u[order].astype(np.float64) / step_u), axis=0),
        "faces": quantise.encode_faces(faces, order),
        "rest": quantise.zigzag_deltas(np.rint((rest[order] - origin) / step), axis=0),
    }


def _diagonal(rest: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(rest, axis=0))) if len(rest) else 1.0


def encode_coefficients(topology: bytes, data: CoefficientData, tolerance: float | None = None,
                        knot_rms: float | None = None, knot_cap: float | np.ndarray | None = None,
                        level: int = container.ZSTD_LEVEL, shared_basis: bool = True,
                        spectrum: knotbasis.TrackSpectrum | None = None,
                        knot_refine: np.ndarray | None = None, knot_rank: int | None = None) -> bytes:
    """Coefficients part bytes for the given topology part. The knots are rounded to steps that add at most
    ``knot_rms`` to the RMS vertex distance and move no coordinate by more than ``knot_cap`` (a number, or
    (C, 3) per curve and coordinate; default 4 x knot_rms) when given, else whose error moves no vertex
    coordinate by more than ``tolerance``
    (default: DEFAULT_TOLERANCE of the diagonal); they are stored on a shared time basis plus residual tracks
    where that is smaller (and ``shared_basis`` allows it). ``spectrum``: the knots' track spectrum when the
    caller has it (:func:`pdeanim.model.knotbasis.track_spectrum` of these knots), else it is computed.
    ``knot_refine`` (C, 3): halve those items' steps that many times more (a rate control's per-curve
    refinement); ``knot_rank``: store the knots on exactly that many shared tracks (0: plain tracks) instead
    of choosing."""
    topo = decode_topology(*container.unpack(topology))
    header, arrays = coefficient_arrays(topology_id(topology), topo, data, tolerance, knot_rms, knot_cap,
                                        shared_basis, spectrum, knot_refine=knot_refine, knot_rank=knot_rank)
    return container.pack(header, arrays, {name: container.SMALLEST for name in arrays}, level)


def coefficient_arrays(topo_id: str, topo: TopologyData, data: CoefficientData,
                       tolerance: float | None = None, knot_rms: float | None = None,
                       knot_cap: float | np.ndarray | None = None,
                       shared_basis: bool = True, spectrum: knotbasis.TrackSpectrum | None = None,
                       choose: bool = True, knot_refine: np.ndarray | None = None,
                       knot_rank: int | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of the coefficients part before packing, on the decoded topology ``topo``
    (:func:`decode_coefficients` reads them as they are). ``choose`` False skips every choice made by trial
    compression (the order of the knot differences, and the rank unless ``knot_rank`` fixes it: then plain
    tracks): the same decoded knots, for a rate control that measures errors, not bytes."""
    family = np.asarray(data.family, np.uint8)
    m = np.asarray(data.m, np.float32)
    steps = _knot_steps(topo, data, family, m, tolerance, knot_rms, knot_cap)
    if knot_refine is not None:
        steps = quantise.refined_steps(steps, knot_refine, data.knots)
    if knot_rank is None and not choose or not shared_basis:
        knot_rank = 0
    if spectrum is None and knot_rank != 0:
        spectrum = knotbasis.track_spectrum(topo.curves, topo.u, family, m, data.D, data.knots)
    codes = _knot_encoding(data, steps, spectrum, choose, knot_rank)
    header = data.header if not codes.shared else {**data.header, SHARED_KEY: True}
    C = family.shape[1]
    fields = CoefficientFields(
        data.segment_t, data.frame_times, family[0] % 2 if len(family) else np.zeros((C, 3), np.uint8),
        data.spline_items(), np.where((family >= 2) & (m > 0), -m, m), data.D, data.motion, data.looping)
    layer_header, layer_arrays = ({}, {}) if data.bones is None else bones_header_arrays(data.bones)
    return write_coefficients(fields, codes, topo_id, header, extra_header=layer_header,
                              extra_arrays={**data.extra, **layer_arrays})


def _knot_steps(topo: TopologyData, data: CoefficientData, family: np.ndarray, m: np.ndarray,
                tolerance: float | None, knot_rms: float | None, knot_cap: float | np.ndarray | None
                ) -> np.ndarray:
    """(C, 3) float32 power-of-two knot steps for an RMS budget (and cap), or for a per-coordinate
    tolerance (docs/compression.md)."""
    tol = tolerance if tolerance is not None else DEFAULT_TOLERANCE * _diagonal(topo.rest)
    spline = data.spline_items()
    tangents = spline.astype(np.uint8) if spline.any() else None
    cubic_max = quantise.CUBIC_PAIR_MAX
    if tangents is not None:  # the spline's weights at the clip's frames
        ft = np.asarray(data.frame_times, np.float64)
        span = ft[-1] - ft[0] if len(ft) > 1 and ft[-1] > ft[0] else 1.0
        cubic_max = max(cubic_max, spline_weight_bound(data.segment_t, (ft - ft[0]) / span))
    if knot_rms is not None:
        return quantise.knot_steps_rms(topo.curves, topo.u, family, m, data.D, data.knots, knot_rms,
                                       4.0 * knot_rms if knot_cap is None else knot_cap, tangents, cubic_max)
    return quantise.knot_steps(topo.curves, topo.u, family, m, data.D, data.knots, tol, tangents, cubic_max)


def _knot_encoding(data: CoefficientData, steps: np.ndarray, spectrum: knotbasis.TrackSpectrum | None,
                   choose: bool, rank: int | None) -> KnotCodes:
    """The stored knots: on ``rank`` shared tracks (0: plain tracks; a rank whose codes would overflow falls
    back to plain ones; -r: on the leading r of ``data.shared``, a windowed fit's weights), or with ``rank``
    None the smallest encoding; the order of the differences chosen by size only when ``choose``."""
    if rank is None:
        return _smallest_knots(data, steps, spectrum)
    found = None
    if rank < 0 and spectrum is not None and data.shared is not None:
        on = knotbasis.on_shared(spectrum, data.shared, steps, data.looping, -rank)
        if on is not None:
            found, steps = on
    elif rank and spectrum is not None:
        found = knotbasis.basis_of_rank(spectrum, steps, data.looping, rank)
    residual = quantise.quantise_knots(data.knots, steps) if found is None else found.residual
    if choose:
        tracks, order = quantise.encode_knot_tracks(residual)
    else:
        tracks, order = quantise.knot_tracks(residual, 1), 1
    if found is None:
        return KnotCodes(steps, tracks, order)
    return KnotCodes(steps, tracks, order, quantise.zigzag(found.weights), found.basis, shared=rank < 0)


def _smallest_knots(data: CoefficientData, steps: np.ndarray, spectrum: knotbasis.TrackSpectrum | None
                    ) -> KnotCodes:
    """The smallest knot encoding: plain tracks, or one of the shared-basis candidates of ``spectrum`` (plain
    on a tie), held one at a time (each is as large as the knots)."""
    codes = quantise.quantise_knots(data.knots, steps)
    best = KnotCodes(steps, *quantise.encode_knot_tracks(codes))
    size = BASIS_MARGIN * _trial_bytes(best)
    for b in knotbasis.basis_candidates(spectrum, steps, data.looping):
        residual, order = quantise.encode_knot_tracks(b.residual)
        option = KnotCodes(steps, residual, order, quantise.zigzag(b.weights), b.basis)
        del b
        trial = _trial_bytes(option)
        if trial < size:
            best, size = option, trial
    for r in knotbasis.shared_ranks(spectrum, data.shared, steps):
        on = knotbasis.on_shared(spectrum, data.shared, steps, data.looping, r)
        if on is None:
            continue
        residual, order = quantise.encode_knot_tracks(on[0].residual)
        option = KnotCodes(on[1], residual, order, quantise.zigzag(on[0].weights), on[0].basis, shared=True)
        trial = _trial_bytes(option)  # the weights not counted: the clip stores them once for every window
        if trial < size:
            best, size = option, trial
    return best


def _trial_bytes(codes: KnotCodes) -> int:
    """Compressed size of the knot arrays at the trial level (the choice must not depend on the final level:
    the fit measures the clip of its trial encodings)."""
    arrays = codes.arrays()
    if codes.shared:
        del arrays["knot_weights"]
    packed = container.pack({}, arrays, {name: container.SMALLEST for name in arrays}, TRIAL_LEVEL)
    return len(packed)


def _need(arrays: dict[str, np.ndarray], name: str, shape: tuple[int | None, ...], part: str,
          dtype: str | None = None) -> np.ndarray:
    if name not in arrays:
        raise ClipFormatError(f"{part} part has no {name!r} array")
    a = arrays[name]
    if dtype is not None and a.dtype.str.replace("|", "<") != dtype:
        raise ClipFormatError(f"{part} array {name!r} has dtype {a.dtype.str}, expected {dtype}")
    if a.ndim != len(shape) or any(
        want is not None and have != want for have, want in zip(a.shape, shape, strict=True)
    ):
        raise ClipFormatError(f"{part} array {name!r} has shape {a.shape}, expected {shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ClipFormatError(f"{part} array {name!r} has non-finite values")
    return a


def decode_topology(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> TopologyData:
    """Validated topology data from a decoded container; raises ClipFormatError."""
    V = _count(header, "n_vertices", "topology")
    lengths = _need(arrays, "curve_lengths", (None,), "topology", "<u4").astype(np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    order_raw = quantise.undo_zigzag_deltas(_need(arrays, "order", (V,), "topology", "<u4"))
    if order_raw.size and (order_raw.min() < 0 or order_raw.max() >= V):
        raise ClipFormatError("topology order holds an index outside the vertices")
    order = order_raw.astype(np.int32)
    curves = _valid_curves(order, offsets.astype(np.int64), V)
    faces = quantise.decode_faces(_need(arrays, "faces", (None, 3), "topology", "<u4"), order)
    zu = _need(arrays, "u", (V, None), "topology", "<u4")
    u_step, rest_step, origin = _steps(header)
    u = np.empty(zu.shape, np.float32)
    u[order] = quantise.dequantise(quantise.undo_zigzag_deltas(zu, axis=0), u_step)
    rest = np.empty((V, 3), np.float32)
    zr = _need(arrays, "rest", (V, 3), "topology", "<u4")
    rest[order] = quantise.dequantise(quantise.undo_zigzag_deltas(zr, axis=0), rest_step, origin)
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(rest))):
        raise ClipFormatError("topology u or rest decode to non-finite values")
    _bounded(rest, "topology rest")
    if faces.size and (faces.min() < 0 or faces.max() >= V):
        raise ClipFormatError("topology faces index outside the vertices")
    if u.shape[1] not in (1, 3):
        raise ClipFormatError(f"topology array 'u' must have 1 or 3 columns, got {u.shape[1]}")
    if u.size and (u.min() < 0 or u.max() > 1):
        raise ClipFormatError("topology curve parameters u must lie in [0, 1]")
    return TopologyData(curves, np.broadcast_to(u, (V, 3)), faces.astype(np.int32), rest,
                        str(header.get("param_mode", "chord")))


def _count(header: dict[str, Any], key: str, part: str) -> int:
    """A non-negative integer header field; raises ClipFormatError for anything else."""
    value = header.get(key)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise ClipFormatError(f"{part} header field {key!r} must be a non-negative integer, got {value!r}")
    return value


def _valid_curves(order: np.ndarray, offsets: np.ndarray, V: int) -> CurveSet:
    if offsets.size and (offsets.min() < -(2**31) or offsets.max() >= 2**31):
        raise ClipFormatError("topology curve offsets do not fit in int32")
    curves = CurveSet(order, offsets.astype(np.int32))
    try:
        return curves.validate(V)
    except Exception as exc:
        raise ClipFormatError(f"topology curves are invalid: {exc}") from exc


def _steps(header: dict[str, Any]) -> tuple[float, float, np.ndarray]:
    """(u_step, rest_step, rest_origin (3,)) of a topology header."""
    try:
        values = [header["u_step"], header["rest_step"], *header["rest_origin"]]
        numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        if len(values) != 5 or not numbers:
            raise TypeError("steps and origin must be 5 JSON numbers")
        u_step, rest_step, origin = float(values[0]), float(values[1]), np.asarray(values[2:], np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise ClipFormatError(f"topology header lacks valid u_step, rest_step or rest_origin: {exc}") from exc
    if not (u_step > 0 and rest_step > 0 and np.all(np.isfinite([u_step, rest_step, *origin]))):
        raise ClipFormatError("topology steps must be positive and finite")
    return u_step, rest_step, origin


def _segment_t(arrays: dict[str, np.ndarray], S: int) -> np.ndarray:
    """(S+1,) segment boundaries: stored, or with a knot at every frame derived from ``frame_times``."""
    if "segment_t" in arrays:
        return _need(arrays, "segment_t", (S + 1,), "coefficients", "<f8")
    ft = _need(arrays, "frame_times", (None,), "coefficients", "<f8")
    if len(ft) != S + 1 or not ft[-1] > ft[0]:
        raise ClipFormatError("coefficients without segment_t need a knot at every frame (n_segments + 1 "
                              "frame times) and a last frame time after the first")
    return frame_segment_t(ft)


def decode_coefficients(header: dict[str, Any], arrays: dict[str, np.ndarray], n_curves: int
                        ) -> CoefficientData:
    """Validated coefficient data from a decoded container; raises ClipFormatError."""
    S, C = _count(header, "n_segments", "coefficients"), int(n_curves)
    seg_t = _segment_t(arrays, S)
    if S < 1 or np.any(np.diff(seg_t) < 0):
        raise ClipFormatError("segment boundaries must be non-decreasing with at least one segment")
    family, signed = _family(arrays, S, C)
    time_model = _need(arrays, "time_model", (C, 3), "coefficients", "<u1")
    if time_model.size and time_model.max() > TIME_SPLINE:
        raise ClipFormatError("coefficients time_model must be 0 (paper) or 1 (natural spline)")
    spline = time_model == TIME_SPLINE
    if spline.any() and np.any(np.diff(seg_t) <= 0):
        raise ClipFormatError("natural-spline items need strictly increasing segment times")
    if np.any(spline[None] & (signed != 0)):
        raise ClipFormatError("items on the natural spline must have time constant 0 in every segment")
    knots = _knots(header, arrays, S, C)
    motion = str(header.get("motion"))
    if motion not in MOTIONS:
        raise ClipFormatError(f"unknown motion mode {motion!r}")
    extra = _rigid_arrays(arrays, C) if motion == "rigid" else {}
    bones = decode_bones(header, arrays) if has_bones(header) else None
    return CoefficientData(seg_t, _need(arrays, "frame_times", (None,), "coefficients", "<f8"), family,
                           np.abs(signed), _need(arrays, "D", (C, 3), "coefficients", "<f4"), knots, motion,
                           bool(header.get("looping", False)), header, extra, time_model, bones)


def _family(arrays: dict[str, np.ndarray], S: int, C: int) -> tuple[np.ndarray, np.ndarray]:
    """(family (S, C, 3) uint8, signed m (S, C, 3) float32): a space kind per curve and coordinate, and the
    signed time constant (< 0: trig time with |m| < pi, > 0: exp, 0: linear)."""
    kind = _need(arrays, "space_kind", (C, 3), "coefficients", "<u1")
    if kind.size and kind.max() > 1:
        raise ClipFormatError("space kinds must be 0 or 1")
    signed = _need(arrays, "m", (S, C, 3), "coefficients", "<f4")
    if np.any(signed <= -np.pi):
        raise ClipFormatError("trig time constants must be above -pi")
    family = (kind[None] + 2 * (signed < 0)).astype(np.uint8)
    return family, signed


def _knots(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int) -> np.ndarray:
    """Knots (S+1, C, 3, 4) float32: the ``knots`` tracks times knot_step, plus with knot_rank r > 0 the
    weights (r, C, 3, 4) times knot_step on the shared time basis (r, S+1) (§3.4)."""
    r = header.get("knot_rank")
    if not isinstance(r, int) or isinstance(r, bool) or not 0 <= r <= S + 1:
        raise ClipFormatError(f"coefficients knot_rank must be an integer in 0..{S + 1}, got {r!r}")
    steps, codes = _knot_tracks(header, arrays, S, C)
    if r == 0:
        if "knot_weights" in arrays or "knot_basis" in arrays:
            raise ClipFormatError("coefficients with knot_rank 0 must not hold knot_weights or knot_basis")
        per_knot = steps[None] if steps.ndim == 2 else steps[_knot_window(arrays, S, len(steps))]
        return _finite_knots(quantise.dequantise(codes, per_knot[..., None]))
    if steps.ndim == 3:
        raise ClipFormatError("knot steps per window (knot_windows) need knot_rank 0")
    weights = quantise.unzigzag(_need(arrays, "knot_weights", (r, C, 3, 4), "coefficients", "<u4"))
    basis = _need(arrays, "knot_basis", (r, S + 1), "coefficients", "<f4")
    return _finite_knots(knotbasis.knots_from_basis(weights, codes, steps, basis))


def _knot_tracks(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(knot_step (C, 3) float32, or (W, C, 3) with knot_windows, integer codes (S+1, C, 3, 4)) of the
    ``knots`` time tracks."""
    if "knot_windows" in arrays:
        W = len(_need(arrays, "knot_windows", (None,), "coefficients", "<u4")) - 1
        steps = _need(arrays, "knot_step", (W, C, 3), "coefficients", "<f4")
    else:
        steps = _need(arrays, "knot_step", (C, 3), "coefficients", "<f4")
    if np.any(steps <= 0):
        raise ClipFormatError("coefficients knot steps must be positive")
    order = header.get("knot_differences")
    if order not in (1, 2) or isinstance(order, bool):
        raise ClipFormatError(f"coefficients knot_differences must be 1 or 2, got {order!r}")
    tracks = _need(arrays, "knots", (C, 3, 4, S + 1), "coefficients", "<u4")
    return steps, quantise.decode_knot_tracks(tracks, order)


def _knot_window(arrays: dict[str, np.ndarray], S: int, W: int) -> np.ndarray:
    """(S+1,) the window of every knot: knot_windows (W+1,) are the first knot of each window and S+1,
    strictly increasing from 0 (§3.4)."""
    bounds = arrays["knot_windows"].astype(np.int64)
    if W < 1 or bounds[0] != 0 or bounds[-1] != S + 1 or np.any(np.diff(bounds) <= 0):
        raise ClipFormatError(f"coefficients knot_windows must rise strictly from 0 to {S + 1}")
    return np.repeat(np.arange(W), np.diff(bounds))


def _finite_knots(knots: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(knots)):
        raise ClipFormatError("coefficients knots decode to non-finite values")
    return _bounded(knots, "coefficients knots")


def _bounded(values: np.ndarray, what: str) -> np.ndarray:
    """``values``, refused when one is above VALUE_LIMIT in magnitude (its frames could overflow float32)."""
    if values.size and not np.abs(values).max() <= VALUE_LIMIT:
        raise ClipFormatError(f"{what} hold a value above 2^96 in magnitude (frames would not be finite)")
    return values


def _rigid_arrays(arrays: dict[str, np.ndarray], C: int) -> dict[str, np.ndarray]:
    """The validated rigid-track arrays of motion "rigid"."""
    seg = _need(arrays, "rigid_segment_t", (None,), "coefficients", "<f8")
    Sr = len(seg) - 1
    if Sr < 1 or np.any(np.diff(seg) < 0):
        raise ClipFormatError("rigid segment boundaries must be non-decreasing with at least one segment")
    centre = _need(arrays, "rigid_centre", (C, 3), "coefficients", "<f4")
    out = {"rigid_segment_t": seg, "rigid_centre": _bounded(centre, "rigid centres")}
    for name in ("rot", "trans"):
        knots = _need(arrays, f"rigid_{name}_knots", (Sr + 1, C, 3), "coefficients", "<f4")
        out[f"rigid_{name}_knots"] = _bounded(knots, f"rigid_{name}_knots")
        mu = _need(arrays, f"rigid_{name}_mu", (Sr, C), "coefficients", "<f4")
        if np.any(mu <= -np.pi):
            raise ClipFormatError("rigid trig time constants must be above -pi")
        out[f"rigid_{name}_mu"] = mu
    return out
