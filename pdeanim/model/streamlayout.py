"""The streamable layout of a dynamic-PDE coefficients part (format 1.2, feature "stream", docs/format.md
§3.10): the time data cut into windows that decode on their own, placed in time order after a small header,
an index and the per-clip arrays, so that a reader plays window 0 once it has that many bytes.

The part is one container: the usual header keys plus ``stream`` (the index: per window its array, byte
range, time range and knot range), the per-clip "head" arrays (frame times, space kinds, time models, space
constants, shared-basis weights, rigid tracks, the bone layer's static arrays), then one raw ``<u1`` array
``window_{i}`` per window holding an inner container with the window's segment times, time constants, knot
steps and knot tracks (differences restart in every window), the knot basis columns, and the natural
spline's state at the window's two end knots (tangents), so that nothing is carried from window to window.

:func:`to_stream` converts any dynamic-PDE clip; :class:`StreamClip` evaluates one (whole, or a prefix of
its bytes); :func:`read_index` reads the index from the first bytes.
"""

from __future__ import annotations

import json
import math
import struct
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import container
from ..clipparts import VALUE_LIMIT, ClipParts
from ..errors import ClipFormatError, ParameterError
from . import quantise
from .bonelayer import CHANNELS, EncodedBones, decode_bones, has_bones
from .clipformat import (
    TIME_SPLINE,
    CoefficientData,
    TopologyData,
    decode_coefficients,
    decode_topology,
)
from .clipmodel import DynamicClip, _info
from .knotbasis import knots_from_basis
from .spline import natural_tangents

STREAM_FEATURE = "stream"
STREAM_VERSION = "1.2"
WINDOW_PART = "coefficients-window"
DEFAULT_WINDOW_SECONDS = 2.0
"""Source seconds per window when the caller gives none: a 30 fps clip's window then holds 60 knots at most,
so the window-bound overhead (one knot and two tangent rows) stays a few percent of its bytes."""
DEFAULT_TANGENT_BITS = 16
"""Bits below the knot step at which the spline's end tangents are stored: the rounding moves a value by at
most 0.15 x 2^-17 of a knot step per unit of the space basis, near float32 rounding for usual steps and far
below the knot's own rounding (half a step). 8 bits left differences of 1e-5 of a clip's size on a test clip
whose knot steps are coarse (fit-absolute-chord-windows); 16 bits, 6e-8 (float32 rounding)."""
MAX_TANGENT_BITS = 30
DECODED_WINDOWS = 4
"""Windows a :class:`StreamClip` keeps decoded (least recently used evicted): memory stays flat however long
the clip."""
HEAD_ORDER = ("frame_times", "space_kind", "time_model", "D", "knot_weights", "rigid_segment_t",
              "rigid_centre", "rigid_rot_knots", "rigid_rot_mu", "rigid_trans_knots", "rigid_trans_mu",
              "bone_pivot", "bone_index", "bone_weight", "bone_time_model", "bone_step")
"""The head arrays of a streamable part, in the order they are written (those the clip has)."""
PER_WINDOW = ("segment_t", "m", "knot_step", "knot_windows", "knots", "knot_basis", "bone_segment_t",
              "bone_m", "bone_knots")
"""Arrays of a 1.0/1.1 part that a streamable part holds per window instead."""
_PREFIX = struct.Struct("<8sII")


def is_stream(header: dict[str, Any]) -> bool:
    """Whether a coefficients header declares the streamable layout (``required`` lists "stream")."""
    required = header.get("required", [])
    return isinstance(required, list) and STREAM_FEATURE in required


# ---------------------------------------------------------------- writer

def to_stream(parts: ClipParts, window_seconds: float = DEFAULT_WINDOW_SECONDS,
              max_window_segments: int | None = None, tangent_bits: int = DEFAULT_TANGENT_BITS,
              level: int = container.ZSTD_LEVEL) -> ClipParts:
    """The clip ``parts`` with its coefficients in the streamable layout (topology and report kept); a part
    already streamable is returned as it is. Raises ParameterError for a clip kind without time windows."""
    coefficients = stream_coefficients(parts.topology, parts.coefficients, window_seconds,
                                       max_window_segments, tangent_bits, level)
    return ClipParts(parts.topology, coefficients, dict(parts.report))


def stream_coefficients(topology: bytes, coefficients: bytes, window_seconds: float = DEFAULT_WINDOW_SECONDS,
                        max_window_segments: int | None = None, tangent_bits: int = DEFAULT_TANGENT_BITS,
                        level: int = container.ZSTD_LEVEL) -> bytes:
    """The streamable coefficients part (docs/format.md §3.10) of a dynamic-PDE clip's parts: windows of about
    ``window_seconds`` of source time (at most ``max_window_segments`` segments each), always cut at the
    source's own windows of knots; the same knots and time constants, the spline state at every window bound
    stored ``tangent_bits`` below the knot step."""
    header, arrays = container.unpack(coefficients)
    if header.get("kind") != "dynamic-pde":
        raise ParameterError(f"only dynamic-pde clips have a streamable layout, not {header.get('kind')!r}")
    if is_stream(header):
        return coefficients
    if not (window_seconds > 0 and math.isfinite(window_seconds)):
        raise ParameterError(f"window_seconds must be a positive number, got {window_seconds!r}")
    if max_window_segments is not None and max_window_segments < 1:
        raise ParameterError(f"max_window_segments must be at least 1, got {max_window_segments!r}")
    if not 0 <= tangent_bits <= MAX_TANGENT_BITS:
        raise ParameterError(f"tangent_bits must lie in 0..{MAX_TANGENT_BITS}, got {tangent_bits!r}")
    topo = decode_topology(*container.unpack(topology))
    C = topo.curves.n_curves
    coef = decode_coefficients(header, arrays, C)
    S = len(coef.segment_t) - 1
    steps, codes = _source_codes(header, arrays, S, C)
    bounds = window_bounds(coef.segment_t, coef.frame_times, arrays.get("knot_windows"), window_seconds,
                           max_window_segments)
    spline = coef.spline_items()
    tangents = _coefficient_tangents(coef.knots, coef.segment_t, spline, bounds)
    bones = coef.bones
    bone_tangents = None
    if bones is not None and np.any(np.asarray(bones.time_model) == TIME_SPLINE):
        P = bones.knots().astype(np.float64).reshape(bones.n_segments + 1, -1)
        bone_tangents = natural_tangents(P, bones.segment_t).reshape(-1, bones.n_bones, CHANNELS)
    order = int(header["knot_differences"])
    rank = int(header["knot_rank"])
    head = {name: arrays[name] for name in HEAD_ORDER if name in arrays}
    out = {name: a for name, a in head.items()}
    encodings = {name: container.SMALLEST for name in head}
    index = []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        blob, extra = _window(i, a, b, coef, steps, codes, order, rank, arrays, spline, tangents,
                              tangent_bits, bones, bone_tangents, level)
        out[f"window_{i}"] = np.frombuffer(blob, np.uint8)
        index.append({"array": f"window_{i}", "t": [float(coef.segment_t[a]), float(coef.segment_t[b])],
                      "knots": [int(a), int(b)], **extra})
    outer = {k: v for k, v in header.items() if k != "arrays"}
    outer.update(format_version=STREAM_VERSION,
                 required=sorted(set(header.get("required", [])) | {STREAM_FEATURE}))
    packed = container.pack(outer, out, encodings, level)
    _, table = container.entries(packed)
    start = _PREFIX.size + _PREFIX.unpack_from(packed, 0)[2]
    where = {name: (lo - start, n) for name, _, _, lo, n, *_ in table}
    for entry in index:
        entry["offset"], entry["nbytes"] = where[entry["array"]]
    return container.with_header(packed, {"stream": {"n_windows": len(index), "windows": index}})


def window_bounds(segment_t: np.ndarray, frame_times: np.ndarray, knot_windows: np.ndarray | None,
                  window_seconds: float, max_window_segments: int | None = None) -> list[int]:
    """Knot indices 0 = k_0 < k_1 < ... < k_W = S where windows start and end: every bound of
    ``knot_windows``, and a new window once the current one spans ``window_seconds`` of source time or
    ``max_window_segments`` segments; a window always has a positive duration (t0 < t1)."""
    seg_t = np.asarray(segment_t, np.float64)
    S = len(seg_t) - 1
    ft = np.asarray(frame_times, np.float64)
    span = float(ft[-1] - ft[0]) if len(ft) > 1 and ft[-1] > ft[0] else 1.0
    seconds = seg_t * span
    forced = set() if knot_windows is None else {int(k) for k in np.asarray(knot_windows)[1:-1]}
    bounds, a = [0], 0
    for k in range(1, S):
        longer = seconds[k] - seconds[a] >= window_seconds * (1.0 - 1e-9) or (  # frame times' rounding
            max_window_segments is not None and k - a >= max_window_segments)
        if (k in forced or longer) and seg_t[k] > seg_t[a] and seg_t[S] > seg_t[k]:
            bounds.append(k)
            a = k
    bounds.append(S)
    return bounds


def _source_codes(header: dict[str, Any], arrays: dict[str, np.ndarray], S: int, C: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(step (S+1, C, 3) float32 of every knot, integer knot codes (S+1, C, 3, 4)) of a 1.0/1.1 part."""
    steps = np.asarray(arrays["knot_step"], np.float32)
    codes = quantise.decode_knot_tracks(arrays["knots"], int(header["knot_differences"]))
    if steps.ndim == 3:
        bounds = np.asarray(arrays["knot_windows"], np.int64)
        steps = steps[np.repeat(np.arange(len(steps)), np.diff(bounds))]
    else:
        steps = np.broadcast_to(steps, (S + 1, C, 3))
    return steps, codes


def _coefficient_tangents(knots: np.ndarray, segment_t: np.ndarray, spline: np.ndarray, bounds: list[int]
                          ) -> np.ndarray | None:
    """(W+1, C, 3, 4) float64 natural-spline tangents of the spline items' knot coefficients at the window
    bounds (0 for other items), or None without spline items."""
    if not spline.any():
        return None
    items = np.flatnonzero(spline.reshape(-1))
    S1, C = knots.shape[0], knots.shape[1]
    flat = knots.reshape(S1, C * 3, 4)
    out = np.zeros((len(bounds), C * 3, 4))
    for a in range(0, len(items), 4096):  # bounded float64 scratch for long clips
        cols = items[a:a + 4096]
        T = natural_tangents(flat[:, cols].astype(np.float64), segment_t)
        out[:, cols] = T[bounds]
    return out.reshape(len(bounds), C, 3, 4)


def _tangent_codes(T: np.ndarray, h: np.ndarray, delta: float, bits: int) -> tuple[np.ndarray, int]:
    """(int64 codes (C, 3, 4), bits) of tangent coefficients T (C, 3, 4) on the step h (C, 3) x 2^-bits /
    delta, with ``bits`` lowered until every code fits a signed 32-bit integer."""
    while True:
        g = np.rint(T * delta * (2.0**bits) / h.astype(np.float64)[..., None])
        if np.abs(g).max(initial=0.0) < 2**30 or bits == 0:
            break
        bits -= 1
    if np.abs(g).max(initial=0.0) >= 2**30:
        raise ParameterError("a spline tangent is too large for the streamable layout's codes")
    return g.astype(np.int64), bits


def _window(i: int, a: int, b: int, coef: CoefficientData, steps: np.ndarray, codes: np.ndarray, order: int,
            rank: int, arrays: dict[str, np.ndarray], spline: np.ndarray, tangents: np.ndarray | None,
            tangent_bits: int, bones: EncodedBones | None, bone_tangents: np.ndarray | None, level: int
            ) -> tuple[bytes, dict[str, Any]]:
    """(inner container bytes, index keys) of window i over knots a..b."""
    header: dict[str, Any] = {"part": WINDOW_PART, "format_version": STREAM_VERSION, "window": i,
                              "first_knot": int(a), "last_knot": int(b)}
    seg_t = np.asarray(coef.segment_t, np.float64)[a:b + 1]
    m = np.asarray(arrays["m"], np.float32)[a:b]
    out: dict[str, np.ndarray] = {
        "segment_t": seg_t, "m": m,
        "knot_step": np.stack([steps[a], steps[b]]).astype(np.float32),
        "knots": quantise.knot_tracks(codes[a:b + 1], order),
    }
    if rank:
        out["knot_basis"] = np.asarray(arrays["knot_basis"], np.float32)[:, a:b + 1]
    if tangents is not None:  # rows i and i + 1: the tangents at this window's bounds
        ends = [(np.where(spline[..., None], tangents[i + e], 0.0), steps[(a, b)[e]],
                 float(seg_t[1] - seg_t[0]) if e == 0 else float(seg_t[-1] - seg_t[-2])) for e in (0, 1)]
        bits = min(_tangent_codes(T, h, delta, tangent_bits)[1] for T, h, delta in ends)
        header["tangent_bits"] = bits  # one precision for both ends (lowered only if a code would overflow)
        out["tangents"] = quantise.zigzag(np.stack([_tangent_codes(T, h, delta, bits)[0]
                                                    for T, h, delta in ends]))
    extra: dict[str, Any] = {}
    if bones is not None:
        bst = np.asarray(bones.segment_t, np.float64)
        Sb = len(bst) - 1
        j0 = min(int(np.searchsorted(bst, seg_t[0], side="right")) - 1, Sb - 1)
        j1 = max(int(np.searchsorted(bst, seg_t[-1], side="left")), j0 + 1)
        header.update(first_bone_knot=j0, last_bone_knot=j1)
        extra["bone_knots"] = [j0, j1]
        out["bone_segment_t"] = bst[j0:j1 + 1]
        out["bone_m"] = np.asarray(bones.mu, np.float32)[j0:j1]
        out["bone_knots"] = quantise.knot_tracks(np.asarray(bones.codes)[j0:j1 + 1], bones.knot_differences)
        if bone_tangents is not None:
            out["bone_tangents"] = np.stack([bone_tangents[j0], bone_tangents[j1]]).astype(np.float64)
    blob = container.pack(header, out, {name: container.SMALLEST for name in out}, level)
    return blob, extra


# ---------------------------------------------------------------- reader

@dataclass(frozen=True)
class WindowEntry:
    """One window of the index: its array, byte range (from the part's start), times and knots."""

    index: int
    array: str
    start: int  # first byte in the part
    nbytes: int
    t0: float
    t1: float
    first_knot: int
    last_knot: int
    bone_knots: tuple[int, int] | None

    @property
    def end(self) -> int:
        return self.start + self.nbytes


def header_length(prefix: bytes) -> int | None:
    """Bytes of a part's prefix and JSON header (what :func:`read_index` needs), or None when ``prefix``
    is shorter than the 16-byte prefix."""
    if len(prefix) < _PREFIX.size:
        return None
    magic, _, hlen = _PREFIX.unpack_from(prefix, 0)
    if magic != container.MAGIC:
        raise ClipFormatError("not a pdeanim container (bad magic bytes)")
    return _PREFIX.size + hlen


def read_index(prefix: bytes) -> tuple[dict[str, Any], list[tuple], list[WindowEntry]]:
    """(header without its arrays table, the checked head-array entries (as container.entries gives them,
    offsets from the part's start), the windows) of a streamable part from its first bytes: the prefix and
    header suffice (the arrays need not be there yet). Raises ClipFormatError for a damaged index."""
    need = header_length(prefix)
    if need is None or need > len(prefix):
        raise ClipFormatError("the streamable part's header is not complete in the bytes given")
    magic, version, hlen = _PREFIX.unpack_from(prefix, 0)
    if version != container.VERSION:
        raise ClipFormatError(f"unsupported container version {version}")
    try:
        header = json.loads(bytes(prefix[_PREFIX.size:need]).decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ClipFormatError(f"container header is not valid JSON: {exc}") from exc
    if not isinstance(header, dict) or not isinstance(header.get("arrays"), dict):
        raise ClipFormatError("container header must be a JSON object with an 'arrays' object")
    table = header.pop("arrays")
    ends = [need]
    for spec in table.values():
        try:
            ends.append(need + int(spec["offset"]) + int(spec["nbytes"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ClipFormatError("bad array entry in the container header") from exc
    total = max(ends)
    entries = {name: container._entry(name, spec, need, total) for name, spec in table.items()}
    windows = _check_index(header, entries, need)
    names = {w.array for w in windows}
    head = [e for name, e in entries.items() if name not in names]
    return header, head, windows


def _check_index(header: dict[str, Any], entries: dict[str, tuple], data_start: int) -> list[WindowEntry]:
    """The windows of a streamable header's ``stream`` index, checked against the arrays table and each
    other (docs/format.md §3.10)."""
    def bad(why: str) -> ClipFormatError:
        return ClipFormatError(f"damaged stream index: {why}")

    stream = header.get("stream")
    if not isinstance(stream, dict) or not isinstance(stream.get("windows"), list):
        raise bad("the header has no 'stream' object with a 'windows' list")
    raw = stream["windows"]
    S = header.get("n_segments")
    if not isinstance(S, int) or isinstance(S, bool) or S < 1:
        raise bad(f"n_segments must be a positive integer, got {S!r}")
    if stream.get("n_windows") != len(raw) or not raw:
        raise bad(f"n_windows {stream.get('n_windows')!r} does not match the {len(raw)} windows listed")
    bones = has_bones(header)
    out: list[WindowEntry] = []
    for i, w in enumerate(raw):
        try:
            name, off, n = w["array"], w["offset"], w["nbytes"]
            t0, t1 = (float(x) for x in w["t"])
            a, b = (int(x) for x in w["knots"])
            if not all(isinstance(x, int) and not isinstance(x, bool) for x in (off, n, *w["knots"])):
                raise TypeError("integers expected")
            bk = None if not bones else tuple(int(x) for x in w["bone_knots"])
        except (KeyError, TypeError, ValueError) as exc:
            raise bad(f"window {i} lacks a valid array, offset, nbytes, t, knots{' or bone_knots' * bones}"
                      ) from exc
        entry = entries.get(name)
        if entry is None:
            raise bad(f"window {i} names array {name!r}, which the part does not hold")
        _, dtype, shape, lo, stored, encoding, _ = entry
        if dtype.str.replace("|", "<") != "<u1" or encoding is not None or len(shape) != 1:
            raise bad(f"window {i}'s array {name!r} must be raw uint8")
        start = lo  # the table's offsets count from the data start, ``lo`` from the part's start
        if lo - data_start != off or stored != n:
            raise bad(f"window {i}'s offset/nbytes ({off}, {n}) differ from array {name!r}'s entry")
        if bk is not None and (len(bk) != 2 or not 0 <= bk[0] < bk[1]):
            raise bad(f"window {i}'s bone_knots {bk!r} are not an increasing pair")
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1 and 0 <= a < b <= S):
            raise bad(f"window {i} has times {t0}..{t1} or knots {a}..{b} out of order")
        if i == 0 and (a != 0 or t0 != 0.0):
            raise bad("window 0 must start at knot 0 and t = 0")
        if i and (a != out[-1].last_knot or t0 != out[-1].t1 or start <= out[-1].start):
            raise bad(f"window {i} does not start where window {i - 1} ends (knot, time or bytes)")
        out.append(WindowEntry(i, name, start, n, t0, t1, a, b, bk))
    if out[-1].last_knot != S or out[-1].t1 != 1.0:
        raise bad(f"the last window must end at knot {S} and t = 1")
    return out


class StreamHead:
    """What a streamable part's windows decode against: the header, the head arrays and the topology."""

    def __init__(self, topo: TopologyData, header: dict[str, Any], head: dict[str, np.ndarray],
                 windows: list[WindowEntry]):
        self.topo, self.header, self.head, self.windows = topo, header, head, windows
        self.C = topo.curves.n_curves
        bad = [name for name in PER_WINDOW if name in head]
        if bad:
            raise ClipFormatError(f"a streamable part holds {', '.join(bad)} in its windows, not its head")
        self.rank = header.get("knot_rank")
        self.bones_static = None
        if has_bones(header):
            self.bones_static = self._static_bones()
        frame_times = head.get("frame_times")
        if frame_times is None:
            raise ClipFormatError("coefficients part has no 'frame_times' array")
        self.frame_times = np.asarray(frame_times, np.float64)
        self.starts = np.array([w.t0 for w in windows])

    def _static_bones(self) -> EncodedBones:
        """The bone layer's per-clip arrays, checked as §3.9 checks them (with placeholder tracks)."""
        B = self.header.get("n_bones")
        if not isinstance(B, int) or isinstance(B, bool) or B < 1:
            raise ClipFormatError(f"bone layer header key 'n_bones' must be a positive integer, got {B!r}")
        probe = dict(self.head, bone_segment_t=np.array([0.0, 1.0]),
                     bone_m=np.zeros((1, B, CHANNELS), np.float32),
                     bone_knots=np.zeros((B, CHANNELS, 2), np.uint32))
        return decode_bones(self.header, probe, len(self.topo.rest))

    def window(self, i: int, blob: bytes) -> DynamicClip:
        """The evaluator of window i from its inner container bytes; raises ClipFormatError."""
        w = self.windows[i]
        wh, wa = container.unpack(blob)
        if wh.get("part") != WINDOW_PART:
            raise ClipFormatError(f"window {i} is not a '{WINDOW_PART}' container")
        if (wh.get("window"), wh.get("first_knot"), wh.get("last_knot")) != (i, w.first_knot, w.last_knot):
            raise ClipFormatError(f"damaged stream index: window {i}'s own header disagrees with the index")
        S = w.last_knot - w.first_knot
        header = {k: v for k, v in self.header.items() if k not in ("required", "stream")}
        header["n_segments"] = S
        arrays = {**{k: v for k, v in self.head.items() if not k.startswith("bone_")},
                  **{k: wa[k] for k in ("segment_t", "m", "knots", "knot_basis") if k in wa}}
        steps = wa.get("knot_step")
        if steps is None or steps.ndim != 3 or steps.shape[0] != 2:
            raise ClipFormatError(f"window {i} needs a knot_step array of shape (2, C, 3)")
        if np.array_equal(steps[0], steps[1]):
            arrays["knot_step"] = steps[0]
        elif self.rank:
            raise ClipFormatError(f"window {i}: knots on a shared basis have one knot step")
        else:  # the last knot starts the next window of knots (§3.4)
            arrays["knot_step"] = steps
            arrays["knot_windows"] = np.array([0, S, S + 1], np.uint32)
        basis = arrays.pop("knot_basis", None)
        weights = arrays.pop("knot_weights", None)
        header["knot_rank"] = 0  # the plain tracks first; the shared basis part below (§3.4)
        coef = decode_coefficients(header, arrays, self.C)
        if self.rank:
            coef.knots = self._basis_knots(i, S, wa, basis, weights, steps[0])
        if not np.array_equal(coef.segment_t[[0, -1]], [w.t0, w.t1]):
            raise ClipFormatError(f"damaged stream index: window {i}'s segment times do not match its range")
        ends = self._tangents(i, wh, wa, coef, steps)
        bone_ends = None
        if self.bones_static is not None:
            coef.bones, bone_ends = self._window_bones(i, w, wh, wa)
        return DynamicClip(self.topo, coef, end_tangents=ends, bone_end_tangents=bone_ends)

    def _basis_knots(self, i: int, S: int, wa: dict[str, np.ndarray], basis: np.ndarray | None,
                     weights: np.ndarray | None, step: np.ndarray) -> np.ndarray:
        """Window i's knots (S+1, C, 3, 4) on the shared time basis: the head's weights, the window's basis
        columns and residual tracks (§3.4)."""
        r, C = self.rank, self.C
        if not isinstance(r, int) or isinstance(r, bool) or r < 0:
            raise ClipFormatError(f"coefficients knot_rank must be a non-negative integer, got {r!r}")
        if weights is None or weights.shape != (r, C, 3, 4) or weights.dtype.str != "<u4":
            raise ClipFormatError(f"a streamable part of knot_rank {r} needs knot_weights ({r}, {C}, 3, 4)")
        basis = _win({"knot_basis": basis} if basis is not None else {}, "knot_basis", (r, S + 1), "<f4", i)
        codes = quantise.decode_knot_tracks(wa["knots"], int(self.header["knot_differences"]))
        knots = knots_from_basis(quantise.unzigzag(weights), codes, step, basis)
        if not np.all(np.isfinite(knots)) or (knots.size and not np.abs(knots).max() <= VALUE_LIMIT):
            raise ClipFormatError(f"window {i}'s knots decode to non-finite values or values above 2^96")
        return knots

    def _tangents(self, i: int, wh: dict[str, Any], wa: dict[str, np.ndarray], coef: CoefficientData,
                  steps: np.ndarray) -> np.ndarray | None:
        """(2, C, 3, 4) float64 end tangent coefficients of window i's spline items (§3.10)."""
        if not coef.spline_items().any():
            return None
        g = wa.get("tangents")
        if g is None or g.shape != (2, self.C, 3, 4) or g.dtype.str != "<u4":
            raise ClipFormatError(f"window {i} has spline items and needs tangents (2, {self.C}, 3, 4) "
                                  "uint32")
        bits = wh.get("tangent_bits")
        if not isinstance(bits, int) or isinstance(bits, bool) or not 0 <= bits <= MAX_TANGENT_BITS:
            raise ClipFormatError(f"window {i}'s tangent_bits must be an integer in 0..{MAX_TANGENT_BITS}")
        seg = coef.segment_t
        deltas = np.array([seg[1] - seg[0], seg[-1] - seg[-2]])
        scale = 2.0 ** -bits
        h = steps.astype(np.float64)[..., None]  # (2, C, 3, 1)
        return ((quantise.unzigzag(g).astype(np.float64) * h) * scale) / deltas[:, None, None, None]

    def _window_bones(self, i: int, w: WindowEntry, wh: dict[str, Any], wa: dict[str, np.ndarray]
                      ) -> tuple[EncodedBones, np.ndarray | None]:
        """Window i's bone tracks (and spline end tangents) on the head's static bone arrays."""
        static = self.bones_static
        B = static.n_bones
        j0, j1 = w.bone_knots
        if (wh.get("first_bone_knot"), wh.get("last_bone_knot")) != (j0, j1):
            raise ClipFormatError(f"damaged stream index: window {i}'s bone knots disagree with the index")
        Sb = j1 - j0
        probe = dict(self.head, bone_segment_t=np.array([0.0, 1.0]),
                     bone_m=_win(wa, "bone_m", (Sb, B, CHANNELS), "<f4", i),
                     bone_knots=_win(wa, "bone_knots", (B, CHANNELS, Sb + 1), "<u4", i))
        seg = _win(wa, "bone_segment_t", (Sb + 1,), "<f8", i)
        if np.any(np.diff(seg) <= 0) or seg[0] > w.t0 or seg[-1] < w.t1:
            raise ClipFormatError(f"window {i}'s bone_segment_t must increase strictly and cover "
                                  f"{w.t0}..{w.t1}")
        probe["bone_segment_t"] = np.linspace(0.0, 1.0, Sb + 1)  # §3.9's checks, then the window's times
        enc = decode_bones(self.header, probe, len(self.topo.rest))
        enc = EncodedBones(np.array(seg), enc.pivot, enc.index, enc.weight_q, enc.time_model, enc.mu,
                           enc.step, enc.codes, enc.knot_differences, enc.weight_bits)
        ends = None
        if np.any(np.asarray(enc.time_model) == TIME_SPLINE):
            ends = _win(wa, "bone_tangents", (2, B, CHANNELS), "<f8", i)
        return enc, ends


def _win(arrays: dict[str, np.ndarray], name: str, shape: tuple[int, ...], dtype: str, i: int) -> np.ndarray:
    a = arrays.get(name)
    if a is None or a.shape != shape or a.dtype.str.replace("|", "<") != dtype:
        raise ClipFormatError(f"window {i} needs {name!r} of shape {shape} and dtype {dtype}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ClipFormatError(f"window {i}'s {name!r} has non-finite values")
    return a


class StreamClip:
    """A streamable dynamic-PDE clip (docs/format.md §3.10) implementing :class:`pdeanim.clip.Clip`: each
    window decoded on first use from its own bytes, at most ``max_windows`` kept. Built from the whole part,
    or from a prefix of it (:meth:`from_prefix`): then only the windows whose bytes are there evaluate."""

    kind = "dynamic-pde"

    def __init__(self, topology: TopologyData, blob: bytes, max_windows: int = DECODED_WINDOWS):
        header, head_entries, windows = read_index(blob)
        self.header, self.blob, self.max_windows = header, blob, max(1, int(max_windows))
        head: dict[str, np.ndarray] = {}
        decoded = sum(size for *_, size in head_entries)
        if decoded > container.decoded_limit(len(blob)):
            raise ClipFormatError(f"the streamable part's head declares {decoded} bytes once decoded: a "
                                  f"damaged or forged file")
        for name, dtype, shape, lo, n, encoding, size in head_entries:
            if lo + n > len(blob):
                raise ClipFormatError(f"array {name!r} of the head is not in the bytes given (truncated)")
            count = size // dtype.itemsize
            if encoding is None:
                head[name] = np.frombuffer(blob, dtype=dtype, count=count, offset=lo).reshape(shape)
            else:
                head[name] = container.decode_array(bytes(blob[lo:lo + n]), str(encoding), dtype, count,
                                                    name).reshape(shape)
        self.head = StreamHead(topology, header, head, windows)
        self.windows = windows
        self.n_vertices = int(len(topology.rest))
        self.faces = np.asarray(topology.faces, np.int32)
        self.frame_times = self.head.frame_times
        self.looping = bool(header.get("looping", False))
        self._decoded: OrderedDict[int, DynamicClip] = OrderedDict()

    @classmethod
    def from_prefix(cls, topology: TopologyData, prefix: bytes, max_windows: int = DECODED_WINDOWS
                    ) -> StreamClip:
        """The clip of the first bytes of a streamable part (at least its header and head arrays)."""
        return cls(topology, prefix, max_windows)

    def available(self) -> int:
        """How many windows, from window 0 on, have all their bytes."""
        return sum(1 for _ in _while(w.end <= len(self.blob) for w in self.windows))

    def window_clip(self, i: int) -> DynamicClip:
        """The decoded evaluator of window i (decoded now if not held)."""
        clip = self._decoded.get(i)
        if clip is not None:
            self._decoded.move_to_end(i)
            return clip
        w = self.windows[i]
        if w.end > len(self.blob):
            raise ClipFormatError(f"window {i} (bytes {w.start}..{w.end}) is not in the {len(self.blob)} "
                                  f"bytes given (truncated or still downloading)")
        clip = self.head.window(i, bytes(self.blob[w.start:w.end]))
        self._decoded[i] = clip
        while len(self._decoded) > self.max_windows:
            self._decoded.popitem(last=False)
        return clip

    def window_of(self, tw: np.ndarray) -> np.ndarray:
        """Window of every wrapped time (§3.10: the last window whose start is at most tw)."""
        return np.clip(np.searchsorted(self.head.starts, tw, side="right") - 1, 0, len(self.windows) - 1)

    def evaluate(self, t: float | np.ndarray) -> np.ndarray:
        """Positions in the original vertex order: (V, 3) float32 for scalar t, (K, V, 3) for an array."""
        scalar = np.ndim(t) == 0
        ts = np.atleast_1d(np.asarray(t, np.float64))
        if not np.all(np.isfinite(ts)):
            raise ValueError("clip times must be finite")
        tw = ts - np.floor(ts) if self.looping else np.clip(ts, 0.0, 1.0)
        win = self.window_of(tw)
        out = np.empty((len(tw), self.n_vertices, 3), np.float32)
        for i in np.unique(win):
            sel = np.flatnonzero(win == i)
            out[sel] = self.window_clip(int(i)).evaluate(tw[sel])
        return out[0] if scalar else out

    def info(self) -> dict[str, Any]:
        """JSON-able metadata (as a whole clip's, plus the windows)."""
        return stream_info(self.header, self.n_vertices, self.head.C, self.head.topo.param_mode,
                           self.frame_times, self.windows)


def _while(flags: Any) -> Any:
    for f in flags:
        if not f:
            return
        yield f


def stream_info(header: dict[str, Any], n_vertices: int, n_curves: int, param_mode: str,
                frame_times: np.ndarray, windows: list[WindowEntry]) -> dict[str, Any]:
    """:meth:`StreamClip.info` from the part's header, index and frame times."""
    ft = np.asarray(frame_times, np.float64)
    bone_segments = windows[-1].bone_knots[1] if has_bones(header) and windows[-1].bone_knots else None
    info = _info(n_vertices, int(len(ft)), int(header["n_segments"]), n_curves, param_mode, header,
                 float(ft[-1] - ft[0]), bone_segments)
    info["stream"] = {"n_windows": len(windows),
                      "windows": [{"t": [w.t0, w.t1], "bytes": w.nbytes} for w in windows]}
    return info


def stream_clip_from_parts(topology: bytes, coefficients: bytes, max_windows: int = DECODED_WINDOWS
                           ) -> StreamClip:
    """The :class:`StreamClip` of a clip's topology part and streamable coefficients part (or a prefix of
    it)."""
    topo = decode_topology(*container.unpack(topology))
    return StreamClip(topo, coefficients, max_windows)

