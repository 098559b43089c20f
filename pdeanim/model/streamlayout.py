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
DEFAULT_TANGENT_BITS = 4
"""Bits below the knot step at which the spline's end tangents are stored at each inner window bound: the
rounding moves a value by at most 0.15 x 2^-5 of a knot step per unit of the space basis (5% of the knot's own
rounding, half a step), near the bound only. Measured on horse-collapse fitted at 3e-3 (windows of 26
segments): 0 bits 2.6 KB a bound, max difference from the source 1.2e-3 of the diagonal; 4 bits 6.2 KB,
7.8e-5 (RMS 1.7e-6, 0.07% of the clip's RMS error); 8 bits 11 KB, 6.8e-6; 16 bits 23 KB, 5e-8 (float32)."""
MAX_TANGENT_BITS = 30
DECODED_WINDOWS = 4
"""Windows a :class:`StreamClip` keeps decoded (least recently used evicted): memory stays flat however long
the clip."""
HEAD_ORDER = ("frame_times", "space_kind", "time_model", "D", "knot_weights", "rigid_segment_t",
              "rigid_centre", "rigid_rot_knots", "rigid_rot_mu", "rigid_trans_knots", "rigid_trans_mu",
              "bone_pivot", "bone_index", "bone_weight", "bone_time_model", "bone_step")
"""The head arrays of a streamable part, in the order they are written (those the clip has)."""
PER_WINDOW = ("segment_t", "m", "knot_windows", "knots", "knot_basis", "bone_segment_t", "bone_m",
              "bone_knots")
"""Arrays of a 1.0/1.1 part that a streamable part holds per window instead (``knot_step`` is in the head
when one step serves every knot, else per window)."""
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
    if "knot_windows" not in arrays:  # one step for every knot: once, in the head
        head["knot_step"] = arrays["knot_step"]
    out = {name: a for name, a in head.items()}
    encodings = {name: container.SMALLEST for name in head}
    index = []
    tracks = quantise.knot_tracks(codes, order)  # the source's tracks: windows hold consecutive slices
    last = len(bounds) - 2
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        end_tangent = None if tangents is None or i == last else tangents[i + 1]
        blob, extra = _window(i, a, b, coef, None if "knot_step" in head else steps, tracks, rank, arrays,
                              spline, end_tangent, tangent_bits, bones, bone_tangents, level, steps)
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


def _window(i: int, a: int, b: int, coef: CoefficientData, window_steps: np.ndarray | None,
            tracks: np.ndarray, rank: int, arrays: dict[str, np.ndarray], spline: np.ndarray,
            end_tangent: np.ndarray | None, tangent_bits: int, bones: EncodedBones | None,
            bone_tangents: np.ndarray | None, level: int, steps: np.ndarray) -> tuple[bytes, dict[str, Any]]:
    """(inner container bytes, index keys) of window i over knots a..b: the knots after a (window 0: from
    0) as the next slice of the source's tracks, their steps (``window_steps``; None: the head holds the one
    step), the tangent at b unless this is the last window."""
    header: dict[str, Any] = {"part": WINDOW_PART, "format_version": STREAM_VERSION, "window": i,
                              "first_knot": int(a), "last_knot": int(b)}
    first = 0 if i == 0 else a + 1  # the first knot this window stores (knot a is carried in)
    seg_t = np.asarray(coef.segment_t, np.float64)[a:b + 1]
    out: dict[str, np.ndarray] = {
        "segment_t": seg_t, "m": np.asarray(arrays["m"], np.float32)[a:b],
        "knots": np.ascontiguousarray(tracks[..., first:b + 1]),
    }
    if window_steps is not None:  # row 0: knots first..b-1 (unused when there are none), row 1: knot b
        out["knot_step"] = np.stack([window_steps[first if first < b else b], window_steps[b]]).astype(
            np.float32)
    if rank:
        out["knot_basis"] = np.ascontiguousarray(np.asarray(arrays["knot_basis"], np.float32)[:, first:b + 1])
    if end_tangent is not None:
        T = np.where(spline[..., None], end_tangent, 0.0)
        g, bits = _tangent_codes(T, steps[b], float(seg_t[-1] - seg_t[-2]), tangent_bits)
        header["tangent_bits"] = bits
        out["tangents"] = quantise.zigzag(g)
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


@dataclass
class WindowState:
    """What a window hands on to the next (§3.10), at its last knot: the integer code p and, with second
    differences, p - p_prev (the running sums go on), the float32 knot, the spline's tangent coefficients
    (None: no spline items, or the clip's natural end)."""

    codes: np.ndarray  # (C, 3, 4) int64
    slopes: np.ndarray | None  # (C, 3, 4) int64, knot_differences 2 only
    knot: np.ndarray  # (C, 3, 4) float32
    tangent: np.ndarray | None  # (C, 3, 4) float64


@dataclass
class WindowData:
    """A decoded window: its coefficients (knots a..b), the spline's end tangents (None: natural) and bone
    tracks."""

    coef: CoefficientData
    ends: tuple[np.ndarray | None, np.ndarray | None]
    bones: EncodedBones | None = None
    bone_ends: np.ndarray | None = None

    def clip(self, topo: TopologyData) -> DynamicClip:
        """The window's evaluator."""
        return DynamicClip(topo, self.coef, end_tangents=self.ends, bone_end_tangents=self.bone_ends)


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

    def window(self, i: int, blob: bytes, state: WindowState | None = None) -> DynamicClip:
        """The evaluator of window i from its inner container bytes and the state window i-1 hands on (None
        for window 0, or a window that holds its own start state); raises ClipFormatError."""
        return self.decode(i, blob, state)[0].clip(self.topo)

    def decode(self, i: int, blob: bytes, state: WindowState | None = None) -> tuple[WindowData, WindowState]:
        """(window i's decoded data, the state it hands on to window i+1) (§3.10)."""
        w = self.windows[i]
        wh, wa = container.unpack(blob)
        if wh.get("part") != WINDOW_PART:
            raise ClipFormatError(f"window {i} is not a '{WINDOW_PART}' container")
        if (wh.get("window"), wh.get("first_knot"), wh.get("last_knot")) != (i, w.first_knot, w.last_knot):
            raise ClipFormatError(f"damaged stream index: window {i}'s own header disagrees with the index")
        C, S = self.C, w.last_knot - w.first_knot
        first = 0 if i == 0 else 1  # local index of the first knot the window stores
        if i:
            state = self._own_state(i, wa) or state
            if state is None:
                raise ClipFormatError(f"window {i} continues window {i - 1}: decode that one first, or fetch "
                                      f"window {i} with its start state (the per-window route)")
        header = {k: v for k, v in self.header.items() if k not in ("required", "stream")}
        header.update(n_segments=S, knot_rank=0)
        if "knot_step" in wa:
            steps = _win(wa, "knot_step", (2, C, 3), "<f4", i)
        elif "knot_step" in self.head:
            steps = np.broadcast_to(_win(self.head, "knot_step", (C, 3), "<f4", i), (2, C, 3))
        else:
            raise ClipFormatError(f"window {i} has no knot_step, nor has the head")
        if np.any(steps <= 0):
            raise ClipFormatError(f"window {i}'s knot steps must be positive")
        tracks = _win(wa, "knots", (C, 3, 4, S + 1 - first), "<u4", i)
        head = {k: v for k, v in self.head.items() if not k.startswith("bone_") and k != "knot_weights"}
        arrays = {**head, "segment_t": wa.get("segment_t"), "m": wa.get("m"),
                  "knot_step": np.ones((C, 3), np.float32),
                  "knots": np.zeros((C, 3, 4, S + 1), np.uint32)}  # knots decoded below, with the state
        arrays = {k: v for k, v in arrays.items() if v is not None}
        coef = decode_coefficients(header, arrays, C)
        if not np.array_equal(coef.segment_t[[0, -1]], [w.t0, w.t1]):
            raise ClipFormatError(f"damaged stream index: window {i}'s segment times do not match its range")
        order = int(self.header["knot_differences"])
        codes = self._codes(tracks, order, state)  # (S + 1 - first, C, 3, 4) int64
        knots = self._knot_values(i, S, first, wa, codes, steps)
        if i:
            knots = np.concatenate([state.knot[None], knots])
        coef.knots = knots
        spline = coef.spline_items().any()
        start = state.tangent if (i and spline) else None
        end = self._end_tangent(i, wh, wa, coef, steps[1]) if spline and i < len(self.windows) - 1 else None
        data = WindowData(coef, (start, end))
        if self.bones_static is not None:
            data.bones, data.bone_ends = self._window_bones(i, w, wh, wa)
            coef.bones = data.bones
        all_codes = codes if not i else np.concatenate([state.codes[None], codes])
        slope = None if order == 1 else all_codes[-1] - all_codes[-2]
        return data, WindowState(all_codes[-1], slope, knots[-1], end)

    def _own_state(self, i: int, wa: dict[str, np.ndarray]) -> WindowState | None:
        """The start state window i holds itself (``start_*`` arrays, §3.10), or None."""
        if "start_codes" not in wa:
            return None
        C = self.C
        codes = quantise.unzigzag(_win(wa, "start_codes", (C, 3, 4), "<u4", i))
        slope = None
        if int(self.header["knot_differences"]) == 2:
            slope = quantise.unzigzag(_win(wa, "start_slopes", (C, 3, 4), "<u4", i))
        knot = _win(wa, "start_knot", (C, 3, 4), "<f4", i)
        _bounded_knots(knot, i)
        tangent = None
        if np.any(np.asarray(self.head.get("time_model", 0)) == TIME_SPLINE):
            tangent = _win(wa, "start_tangents", (C, 3, 4), "<f8", i)
        return WindowState(codes, slope, np.array(knot), None if tangent is None else np.array(tangent))

    @staticmethod
    def _codes(tracks: np.ndarray, order: int, state: WindowState | None) -> np.ndarray:
        """Integer knot codes (n, C, 3, 4) of a window's tracks, the running sums continuing from
        ``state`` (None: from 0, §3.1)."""
        d = np.moveaxis(quantise.unzigzag(tracks), -1, 0)  # (n, C, 3, 4) decoded differences
        if order == 1:
            return (0 if state is None else state.codes) + np.cumsum(d, axis=0)
        slopes = (0 if state is None else state.slopes) + np.cumsum(d, axis=0)
        return (0 if state is None else state.codes) + np.cumsum(slopes, axis=0)

    def _knot_values(self, i: int, S: int, first: int, wa: dict[str, np.ndarray], codes: np.ndarray,
                     steps: np.ndarray) -> np.ndarray:
        """float32 knots (S + 1 - first, C, 3, 4) of a window's codes: float32(p x h), with h the step of
        knot b for the last, or on the shared basis (§3.4)."""
        r, C = self.rank, self.C
        n = S + 1 - first
        if not r:
            per_knot = np.repeat(steps, [n - 1, 1], axis=0)  # (n, C, 3)
            knots = quantise.dequantise(codes, per_knot[..., None])
        else:
            if not isinstance(r, int) or isinstance(r, bool) or r < 0:
                raise ClipFormatError(f"coefficients knot_rank must be a non-negative integer, got {r!r}")
            weights = self.head.get("knot_weights")
            if weights is None or weights.shape != (r, C, 3, 4) or weights.dtype.str != "<u4":
                raise ClipFormatError(f"a streamable part of knot_rank {r} needs knot_weights "
                                      f"({r}, {C}, 3, 4)")
            if not np.array_equal(steps[0], steps[1]):
                raise ClipFormatError(f"window {i}: knots on a shared basis have one knot step")
            basis = _win(wa, "knot_basis", (r, n), "<f4", i)
            knots = knots_from_basis(quantise.unzigzag(weights), codes, steps[0], basis)
        return _bounded_knots(knots, i)

    def _end_tangent(self, i: int, wh: dict[str, Any], wa: dict[str, np.ndarray], coef: CoefficientData,
                     step: np.ndarray) -> np.ndarray:
        """(C, 3, 4) float64 tangent coefficients of the spline items at window i's last knot (§3.10)."""
        g = _win(wa, "tangents", (self.C, 3, 4), "<u4", i)
        bits = wh.get("tangent_bits")
        if not isinstance(bits, int) or isinstance(bits, bool) or not 0 <= bits <= MAX_TANGENT_BITS:
            raise ClipFormatError(f"window {i}'s tangent_bits must be an integer in 0..{MAX_TANGENT_BITS}")
        seg = coef.segment_t
        h = step.astype(np.float64)[..., None]
        return ((quantise.unzigzag(g).astype(np.float64) * h) * 2.0**-bits) / float(seg[-1] - seg[-2])

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


def _bounded_knots(knots: np.ndarray, i: int) -> np.ndarray:
    if not np.all(np.isfinite(knots)) or (knots.size and not np.abs(knots).max() <= VALUE_LIMIT):
        raise ClipFormatError(f"window {i}'s knots decode to non-finite values or values above 2^96")
    return knots


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
        self._states: dict[int, WindowState] = {}

    @classmethod
    def from_prefix(cls, topology: TopologyData, prefix: bytes, max_windows: int = DECODED_WINDOWS
                    ) -> StreamClip:
        """The clip of the first bytes of a streamable part (at least its header and head arrays)."""
        return cls(topology, prefix, max_windows)

    def available(self) -> int:
        """How many windows, from window 0 on, have all their bytes."""
        return sum(1 for _ in _while(w.end <= len(self.blob) for w in self.windows))

    def _bytes(self, i: int) -> bytes:
        w = self.windows[i]
        if w.end > len(self.blob):
            raise ClipFormatError(f"window {i} (bytes {w.start}..{w.end}) is not in the {len(self.blob)} "
                                  f"bytes given (truncated or still downloading)")
        return bytes(self.blob[w.start:w.end])

    def start_state(self, i: int) -> WindowState | None:
        """The state window i starts from (None for window 0): handed on by window i - 1, whose own start
        state is found the same way (states are kept: a few arrays of (C, 3, 4) per window)."""
        if i == 0:
            return None
        j = i
        while j > 0 and j not in self._states:
            j -= 1
        for k in range(j, i):  # decode the knots of the windows between (their fields are not built)
            _, self._states[k + 1] = self.head.decode(k, self._bytes(k), self._states.get(k))
        return self._states[i]

    def window_data(self, i: int) -> WindowData:
        """Window i decoded (knots, tangents, bone tracks), its hand-on state recorded."""
        data, after = self.head.decode(i, self._bytes(i), self.start_state(i))
        self._states.setdefault(i + 1, after)
        return data

    def window_clip(self, i: int) -> DynamicClip:
        """The decoded evaluator of window i (decoded now if not held)."""
        clip = self._decoded.get(i)
        if clip is not None:
            self._decoded.move_to_end(i)
            return clip
        clip = self.window_data(i).clip(self.head.topo)
        self._decoded[i] = clip
        while len(self._decoded) > self.max_windows:
            self._decoded.popitem(last=False)
        return clip

    def self_contained(self, i: int) -> bytes:
        """Window i's inner container with its start state added (``start_*`` arrays, §3.10): it then
        decodes with the head alone (what the per-window HTTP route serves, for a player that seeks)."""
        blob = self._bytes(i)
        state = self.start_state(i)
        if state is None:
            return blob
        header, arrays = container.unpack(blob)
        extra = {"start_codes": quantise.zigzag(state.codes), "start_knot": state.knot.astype(np.float32)}
        if state.slopes is not None:
            extra["start_slopes"] = quantise.zigzag(state.slopes)
        if state.tangent is not None:
            extra["start_tangents"] = state.tangent.astype(np.float64)
        encodings = container.array_encodings(blob)
        encodings.update({name: container.SMALLEST for name in extra})
        return container.pack(header, {**arrays, **extra}, encodings)

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

