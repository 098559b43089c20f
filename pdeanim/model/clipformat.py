"""The "dynamic-pde" clip format: a topology part and a coefficients part, both pdeanim containers.

Version 2 stores the same model as version 1 below, coded as integers: error-bounded steps
(:mod:`pdeanim.model.quantise`), zigzag differences along time or along the curves, and zstd in the container
(docs/format.md §3.7). Version 3 (written by default where it is smaller, else version 2) changes only how
the coefficients part stores the knots: weights on a few shared time tracks plus residual tracks
(:mod:`pdeanim.model.knotbasis`, §3.9). Version 4 (written by default where some item uses them) adds
Catmull-Rom time tangents: a ``tangents`` (C, 3) uint8 array whose items interpolate their knots on linear
segments with a C1 cubic (:mod:`pdeanim.model.tangents`, §3.10). Versions 1 to 3 are still read, and written
on request.

Topology part (``part: "topology"``, ``model: "dynamic-pde"``, once per mesh + curve layout + rest pose)::

    order    (V,)      int32    vertex indices curve by curve (CurveSet CSR order)
    offsets  (C+1,)    int32    curve c is order[offsets[c]:offsets[c+1]]
    u        (V, 1|3)  float32  curve parameter of every vertex (original order): one column when x, y, z
                                share it (chord length), per coordinate otherwise (paper mode)
    faces    (T, 3)    int32    the mesh's triangles
    rest     (V, 3)    float32  first-frame positions (original order)
    header: format_version 1, n_vertices, n_curves, param_mode

Coefficients part (``part: "coefficients"``, ``kind: "dynamic-pde"``, ``topology_id`` = SHA-256 of the
topology bytes)::

    segment_t   (S+1,)          float64  segment boundaries in normalised clip time t in [0, 1]
    frame_times (F,)            float64  seconds of the source frames (t = 0 and 1 are the first and last)
    family      (S, C, 3)       uint8    family code 0..3 (paper Eq. 5-8) per segment, curve, coordinate
    m           (S, C, 3)       float32  time constant in local segment time tau (>= 0)
    D           (C, 3)          float32  space constant, shared by all segments of a curve+coordinate
    knots       (S+1, C, 3, 4)  float32  balanced space coefficients at the segment ends
    rigid_*     only for motion "rigid" (see pdeanim.model.rigid): rigid_segment_t (Sr+1,) float64,
                rigid_centre (C, 3), rigid_rot_knots / rigid_trans_knots (Sr+1, C, 3) and signed
                rigid_rot_mu / rigid_trans_mu (Sr, C) float32 (> 0 exp, < 0 trig, 0 linear)
    header: format_version 1, motion ("displacement": positions = rest + w; "absolute": positions = w;
            "rigid": positions = R(t) (rest - centre + w) + c(t)),
            looping, n_segments, n_curves, n_frames, errors (summary of the fit)

The 8 coefficients of segment s, curve c, coordinate w are C = [knots[s, c, w], knots[s+1, c, w]] (2, 4):
w(u, tau) = sum_ik C[i, k] phi_i(tau; m) S_k(u; D) in the balanced bases of :mod:`pdeanim.model.families`
(phi0/phi1 interpolate the segment ends, so adjacent segments share their knot: C0 exactly, also in
float32). :func:`pdeanim.model.families.paper_coefficients` converts them to the paper's c1..c8. Storing the
shared knots once instead of 8 values per segment is what makes C0 free and the part ~half the size.

Evaluating without this library (e.g. a JavaScript client), for vertex v on curve c, coordinate w, at t:

1. segment s with segment_t[s] <= t <= segment_t[s+1], tau = (t - segment_t[s]) / (segment_t[s+1] -
   segment_t[s]) (looping clips first take t mod 1);
2. time pair from family[s, c, w] and m = m[s, c, w]: family 0/1 (exp): phi1 = sinh(m tau)/sinh(m),
   phi0 = sinh(m (1-tau))/sinh(m); family 2/3 (trig): sin instead of sinh; m == 0: phi0 = 1-tau, phi1 = tau;
3. space basis S_k(u) with u = u[v, w] (or u[v, 0]), D = D[c, w], space kind D0 (even family) or D1 (odd),
   exactly as :func:`pdeanim.model.families.space_basis` (s = u - 1/2; D < 4: the scaled Taylor-stable set,
   whose small-x ratios need series near x = 0; D >= 4: the bounded exponentials);
4. value = sum_k (phi0 knots[s, c, w, k] + phi1 knots[s+1, c, w, k]) S_k(u); position = rest + value
   (displacement), value (absolute), or R(t) (rest - centre + value) + c(t) for rigid.

Steps 3 and the knot products do not depend on t and can be precomputed per vertex.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import container
from ..clip import topology_id
from ..curveset import CurveSet
from ..errors import ClipFormatError
from . import knotbasis, quantise
from .tangents import spline_weight_bound

TRIAL_LEVEL = 3
"""zstd level of trial encodings (the fit's rounding search, its choice between fits, and the choice between
knot encodings): fast, and about proportional to the final level 19 sizes; only the clip that is kept is
compressed at container.ZSTD_LEVEL."""

FORMAT_VERSION = 5
FORMAT_VERSIONS = (1, 2, 3, 4, 5)
"""Versions a writer may be asked for. Version 3 adds the knot basis (§3.9) to the coefficients part only: a
clip asked for in version 3 whose knots code smaller without a basis is written as version 2, and its
topology part is version 2 either way. Version 4 adds Catmull-Rom time tangents (§3.10): a clip asked for in
version 4 without any is written as version 3 (or 2). Version 5 (§3.11) has natural-spline tangents instead;
the same rule."""
TOPOLOGY_VERSIONS = (1, 2)
MOTIONS = ("displacement", "absolute", "rigid")
DEFAULT_TOLERANCE = 1e-5
"""Quantisation tolerance of version 2 relative to the rest pose's bounding-box diagonal, when the caller
gives none (a fit with error targets passes a share of its target)."""


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
    """Decoded coefficients part (see the module docstring for shapes)."""

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
    tangents: np.ndarray | None = None  # (C, 3) uint8, 1: cubic linear segments (versions 4, 5); None: none
    spline_tangents: bool = False  # the cubic's tangents: natural spline (version 5), else Catmull-Rom (4)


def encode_topology(curves: CurveSet, u: np.ndarray, faces: np.ndarray, rest: np.ndarray,
                    param_mode: str, version: int = FORMAT_VERSION, tolerance: float | None = None,
                    level: int = container.ZSTD_LEVEL) -> bytes:
    """Topology part bytes from curves, u (V, 3), faces (T, 3), rest (V, 3); version 2 rounds rest to a
    step whose error is at most ``tolerance`` (default: DEFAULT_TOLERANCE of the diagonal) and compresses
    at zstd ``level`` (a trial encoding may use a fast one)."""
    _check_version(version)
    version = min(version, 2)  # version 3 changes the coefficients part only
    header = {"part": "topology", "model": "dynamic-pde", "format_version": version,
              "n_vertices": int(len(rest)), "n_curves": curves.n_curves, "param_mode": param_mode}
    u = np.asarray(u, np.float32)
    if (
        u.ndim == 2
        and u.shape[1] == 3
        and np.array_equal(u[:, :1], u[:, 1:2])
        and np.array_equal(u[:, :1], u[:, 2:])
    ):
        u = u[:, :1]
    if version == 1:
        return container.pack(header, {
            "order": np.asarray(curves.order, np.int32), "offsets": np.asarray(curves.offsets, np.int32),
            "u": u, "faces": np.asarray(faces, np.int32).reshape(-1, 3),
            "rest": np.asarray(rest, np.float32)})
    rest = np.asarray(rest, np.float32)
    tol = tolerance if tolerance is not None else DEFAULT_TOLERANCE * _diagonal(rest)
    origin, step = quantise.rest_origin_step(rest, tol)
    order = np.asarray(curves.order, np.int64)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    step_u = quantise.u_step(u)
    header.update({"rest_origin": [float(x) for x in origin], "rest_step": step, "u_step": step_u})
    arrays = {
        "curve_lengths": np.diff(np.asarray(curves.offsets, np.int64)).astype(np.uint32),
        "order": quantise.zigzag_deltas(order),
        "u": quantise.zigzag_deltas(np.rint(u[order].astype(np.float64) / step_u), axis=0),
        "faces": quantise.encode_faces(faces, order),
        "rest": quantise.zigzag_deltas(np.rint((rest[order] - origin) / step), axis=0),
    }
    return container.pack(header, arrays, {name: container.SMALLEST for name in arrays}, level)


def _diagonal(rest: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(rest, axis=0))) if len(rest) else 1.0


def _check_version(version: int) -> None:
    if version not in FORMAT_VERSIONS:
        raise ValueError(f"dynamic-pde format version must be one of {FORMAT_VERSIONS}, got {version!r}")


def encode_coefficients(topology: bytes, data: CoefficientData, version: int = FORMAT_VERSION,
                        tolerance: float | None = None, knot_rms: float | None = None,
                        knot_cap: float | None = None, level: int = container.ZSTD_LEVEL) -> bytes:
    """Coefficients part bytes for the given topology part; version 2 rounds the knots to steps that add at
    most ``knot_rms`` to the RMS vertex distance and move no coordinate by more than ``knot_cap`` (default
    4 x knot_rms) when given, else whose error moves no vertex coordinate by more than ``tolerance``
    (default: DEFAULT_TOLERANCE of the diagonal). Version 3 stores the same rounded knots on a shared time
    basis plus residual tracks where that is smaller, and writes version 2 otherwise."""
    _check_version(version)
    S, C = data.family.shape[:2]
    tangents = None
    if data.tangents is not None and np.any(data.tangents):
        tangents = np.asarray(data.tangents, np.uint8)
    if tangents is not None and version < (5 if data.spline_tangents else 4):
        raise ValueError(f"these time tangents need format version {5 if data.spline_tangents else 4}, "
                         f"not {version}")
    header = {**data.header, "part": "coefficients", "kind": "dynamic-pde", "format_version": version,
              "topology_id": topology_id(topology), "motion": data.motion, "looping": bool(data.looping),
              "n_segments": int(S), "n_curves": int(C), "n_frames": int(len(data.frame_times))}
    arrays: dict[str, np.ndarray] = {
        "segment_t": np.asarray(data.segment_t, np.float64),
        "frame_times": np.asarray(data.frame_times, np.float64),
    }
    family = np.asarray(data.family, np.uint8)
    if version == 1:
        arrays.update({"family": family, "m": np.asarray(data.m, np.float32),
                       "D": np.asarray(data.D, np.float32), "knots": np.asarray(data.knots, np.float32),
                       **data.extra})
        return container.pack(header, arrays)
    topo = decode_topology(*container.unpack(topology))
    tol = tolerance if tolerance is not None else DEFAULT_TOLERANCE * _diagonal(topo.rest)
    m = np.asarray(data.m, np.float32)
    cubic_max = quantise.CUBIC_PAIR_MAX
    if tangents is not None and data.spline_tangents:  # the spline's weights at the clip's frames
        ft = np.asarray(data.frame_times, np.float64)
        span = ft[-1] - ft[0] if len(ft) > 1 and ft[-1] > ft[0] else 1.0
        cubic_max = max(cubic_max, spline_weight_bound(data.segment_t, (ft - ft[0]) / span))
    arrays["space_kind"] = (family[0] % 2 if len(family) else np.zeros((C, 3))).astype(np.uint8)
    if knot_rms is not None:
        steps = quantise.knot_steps_rms(topo.curves, topo.u, data.family, m, data.D, data.knots, knot_rms,
                                        4.0 * knot_rms if knot_cap is None else knot_cap, tangents, cubic_max)
    else:
        steps = quantise.knot_steps(topo.curves, topo.u, data.family, m, data.D, data.knots, tol, tangents,
                                    cubic_max)
    codes = quantise.quantise_knots(data.knots, steps)
    tracks, differences = quantise.encode_knot_tracks(codes)
    knot_arrays: dict[str, np.ndarray] = {"knot_step": steps, "knots": tracks}
    header.update(format_version=2, knot_differences=differences)
    if version >= 3:  # the smallest of the plain tracks and the basis encodings (plain on a tie), one held
        best, rank = _trial_bytes(knot_arrays), 0  # at a time: each is as large as the knots
        for b in knotbasis.basis_candidates(topo.curves, topo.u, data.family, m, data.D, data.knots, steps,
                                            data.looping):
            residual, order = quantise.encode_knot_tracks(b.residual)
            option = {"knot_step": steps, "knot_weights": quantise.zigzag(b.weights), "knot_basis": b.basis,
                      "knots": residual}
            del b
            size = _trial_bytes(option)
            if size < best:
                best, knot_arrays, differences, rank = size, option, order, option["knot_weights"].shape[0]
        if rank:
            header.update(format_version=3, knot_differences=differences, knot_rank=rank)
    if tangents is not None:
        header.update(format_version=5 if data.spline_tangents else 4, knot_rank=header.get("knot_rank", 0))
        knot_arrays["tangents"] = tangents
    arrays.update({
        "m": np.where((family >= 2) & (m > 0), -m, m), "D": np.asarray(data.D, np.float32),
        **knot_arrays, **{k: np.asarray(v) for k, v in data.extra.items()}})
    return container.pack(header, arrays, {name: container.SMALLEST for name in arrays}, level)


def _trial_bytes(arrays: dict[str, np.ndarray]) -> int:
    """Compressed size of arrays at the trial level (the choice must not depend on the final level: the fit
    measures the clip of its trial encodings)."""
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
    """Validated topology data from a decoded container (version 1 or 2); raises ClipFormatError."""
    version = header.get("format_version")
    if version not in TOPOLOGY_VERSIONS:
        raise ClipFormatError(f"unsupported dynamic-pde topology version {version!r}")
    V = _count(header, "n_vertices", "topology")
    if version == 1:
        order = _need(arrays, "order", (V,), "topology").astype(np.int32)
        offsets = _need(arrays, "offsets", (None,), "topology").astype(np.int32)
        curves = _valid_curves(order, offsets, V)
        faces = _need(arrays, "faces", (None, 3), "topology")
        u = _need(arrays, "u", (V, None), "topology")
        rest = _need(arrays, "rest", (V, 3), "topology")
    else:
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
    """(u_step, rest_step, rest_origin (3,)) of a version 2 topology header."""
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


def decode_coefficients(
    header: dict[str, Any], arrays: dict[str, np.ndarray], n_curves: int
) -> CoefficientData:
    """Validated coefficient data from a decoded container (version 1 to 4); raises ClipFormatError."""
    version = header.get("format_version")
    if version not in FORMAT_VERSIONS:
        raise ClipFormatError(f"unsupported dynamic-pde coefficients version {version!r}")
    S, C = _count(header, "n_segments", "coefficients"), int(n_curves)
    seg_t = _need(arrays, "segment_t", (S + 1,), "coefficients")
    if S < 1 or np.any(np.diff(seg_t) < 0):
        raise ClipFormatError("segment boundaries must be non-decreasing with at least one segment")
    if version == 1:
        family = _need(arrays, "family", (S, C, 3), "coefficients")
        m = _need(arrays, "m", (S, C, 3), "coefficients")
    else:
        family, m = _family_v2(arrays, S, C)
    if family.size and family.max() > 3:
        raise ClipFormatError("family codes must be 0..3")
    if S > 1 and np.any(family % 2 != family[:1] % 2):
        raise ClipFormatError("the space kind of a curve+coordinate must be the same in every segment")
    if version == 1:
        knots = _need(arrays, "knots", (S + 1, C, 3, 4), "coefficients")
    elif version == 2 or (version >= 4 and header.get("knot_rank") == 0):
        if version >= 4 and ("knot_weights" in arrays or "knot_basis" in arrays):
            raise ClipFormatError("coefficients with knot_rank 0 must not hold knot_weights or knot_basis")
        knots = _knots_v2(header, arrays, S, C)
    else:
        knots = _knots_v3(header, arrays, S, C)
    tangents = _tangents(arrays, C) if version >= 4 else None
    if version == 5 and tangents.any() and np.any(np.diff(seg_t) <= 0):
        raise ClipFormatError("natural-spline tangents (version 5) need strictly increasing segment times")
    if np.any(m < 0) or np.any((family >= 2) & (m >= np.pi)):
        raise ClipFormatError("time constants must be >= 0 (and < pi for trig families)")
    motion = str(header.get("motion"))
    if motion not in MOTIONS:
        raise ClipFormatError(f"unknown motion mode {motion!r}")
    extra = _rigid_arrays(arrays, C) if motion == "rigid" else {}
    return CoefficientData(seg_t, _need(arrays, "frame_times", (None,), "coefficients"), family, m,
                           _need(arrays, "D", (C, 3), "coefficients"),
                           knots, motion,
                           bool(header.get("looping", False)), header, extra, tangents, version == 5)


def _tangents(arrays: dict[str, np.ndarray], C: int) -> np.ndarray:
    """The (C, 3) uint8 tangent flags of a version 4 or 5 coefficients part (0 or 1)."""
    tangents = _need(arrays, "tangents", (C, 3), "coefficients", "<u1")
    if tangents.size and tangents.max() > 1:
        raise ClipFormatError("coefficients tangents must be 0 or 1")
    return tangents


def _family_v2(arrays: dict[str, np.ndarray], S: int, C: int) -> tuple[np.ndarray, np.ndarray]:
    """(family (S, C, 3) uint8, m >= 0 float32) of a version 2 coefficients part: a space kind per curve and
    coordinate, and signed m (< 0: trig time with |m|, > 0: exp, 0: linear)."""
    kind = _need(arrays, "space_kind", (C, 3), "coefficients", "<u1")
    if kind.size and kind.max() > 1:
        raise ClipFormatError("space kinds must be 0 or 1")
    signed = _need(arrays, "m", (S, C, 3), "coefficients", "<f4")
    family = (kind[None] + 2 * (signed < 0)).astype(np.uint8)
    return family, np.abs(signed)


def _knots_v2(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int) -> np.ndarray:
    """Knots (S+1, C, 3, 4) float32 of a version 2 coefficients part: one track (C, 3, 4, S+1) of zigzag
    differences of order ``knot_differences`` along time per item and coefficient, times knot_step."""
    steps, codes = _knot_tracks(header, arrays, S, C)
    return _finite_knots(quantise.dequantise(codes, steps[None, :, :, None]))


def _knots_v3(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int) -> np.ndarray:
    """Knots (S+1, C, 3, 4) float32 of a version 3 coefficients part: zigzag weight codes (r, C, 3, 4) times
    knot_step on a shared time basis (r, S+1), plus residual tracks coded as the version 2 knots (§3.9)."""
    r = header.get("knot_rank")
    low = 0 if header.get("format_version") == 4 else 1  # version 4's rank 0 decodes as version 2 (caller)
    if not isinstance(r, int) or isinstance(r, bool) or not 1 <= r <= S + 1:
        raise ClipFormatError(f"coefficients knot_rank must be an integer in {low}..{S + 1}, got {r!r}")
    steps, residual = _knot_tracks(header, arrays, S, C)
    codes = quantise.unzigzag(_need(arrays, "knot_weights", (r, C, 3, 4), "coefficients", "<u4"))
    basis = _need(arrays, "knot_basis", (r, S + 1), "coefficients", "<f4")
    return _finite_knots(knotbasis.knots_from_basis(codes, residual, steps, basis))


def _knot_tracks(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(knot_step (C, 3) float32, integer codes (S+1, C, 3, 4)) of the ``knots`` time tracks."""
    steps = _need(arrays, "knot_step", (C, 3), "coefficients", "<f4")
    if np.any(steps <= 0):
        raise ClipFormatError("coefficients knot steps must be positive")
    order = header.get("knot_differences")
    if order not in (1, 2) or isinstance(order, bool):
        raise ClipFormatError(f"coefficients knot_differences must be 1 or 2, got {order!r}")
    tracks = _need(arrays, "knots", (C, 3, 4, S + 1), "coefficients", "<u4")
    return steps, quantise.decode_knot_tracks(tracks, order)


def _finite_knots(knots: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(knots)):
        raise ClipFormatError("coefficients knots decode to non-finite values")
    return knots


def _rigid_arrays(arrays: dict[str, np.ndarray], C: int) -> dict[str, np.ndarray]:
    """The validated rigid-track arrays of motion "rigid"."""
    seg = _need(arrays, "rigid_segment_t", (None,), "coefficients")
    Sr = len(seg) - 1
    if Sr < 1 or np.any(np.diff(seg) < 0):
        raise ClipFormatError("rigid segment boundaries must be non-decreasing with at least one segment")
    out = {"rigid_segment_t": seg, "rigid_centre": _need(arrays, "rigid_centre", (C, 3), "coefficients")}
    for name in ("rot", "trans"):
        out[f"rigid_{name}_knots"] = _need(arrays, f"rigid_{name}_knots", (Sr + 1, C, 3), "coefficients")
        mu = _need(arrays, f"rigid_{name}_mu", (Sr, C), "coefficients")
        if np.any(mu <= -np.pi):
            raise ClipFormatError("rigid trig time constants must be above -pi")
        out[f"rigid_{name}_mu"] = mu
    return out
