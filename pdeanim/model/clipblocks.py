"""A "dynamic-pde" clip evaluated a block of curves at a time, in memory bounded by the block instead of by
the whole clip's segments x vertices (the decoded clip of 1,000 frames x 34k vertices holds 2.3 GiB).

Each vertex lies on one curve, and each curve's items have their own knots, time constants, space constants
and spline, so the clip restricted to a block of curves (the coefficient arrays sliced on their curve axis,
decoded by the same :func:`pdeanim.model.clipformat.decode_coefficients`) is a clip of its own whose positions
are, bit for bit, the whole clip's at those vertices. The arrays that grow with segments x curves are
decompressed once to a scratch file and read back one block at a time.
"""

from __future__ import annotations

import math
import os
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from .. import container
from ..curveset import CurveSet
from ..errors import ClipFormatError
from .clipformat import TopologyData, decode_coefficients, decode_topology
from .clipmodel import DynamicClip

CURVE_AXIS = {"knots": 0, "m": 1, "space_kind": 0, "time_model": 0, "D": 0, "knot_step": -2,
              "knot_weights": 1, "rigid_centre": 0, "rigid_rot_knots": 1, "rigid_trans_knots": 1,
              "rigid_rot_mu": 1, "rigid_trans_mu": 1}
"""The curve axis of every per-curve array of the coefficients part (docs/format.md §3.3, §3.7)."""
SPOOL_BYTES = 4 << 20
"""A compressed array larger than this once decoded is decompressed to a scratch file, not into memory."""
BLOCK_BYTES = 40 << 20
"""About the memory one block's decoded clip may take (its knot fields, tangents and their solve)."""
BYTES_PER_KNOT_VALUE = 72  # per knot and vertex coordinate: fields, tangents, their float64 solve (measured)
BYTES_PER_KNOT_CURVE = 400  # per knot and curve: the block's knot tracks, integer codes and knots
SPLINE_CHUNK = 1 << 16  # values per block of a whole clip's tangent solve (pdeanim.model.clipmodel)
_EVALUATING = threading.Lock()
"""One blocked evaluation at a time per process, so that its memory is one block however many ask."""


def decode_cost(n_segments: int, n_vertices: int, n_curves: int, spline: bool = True) -> int:
    """About the peak memory of decoding a whole clip of these sizes (:func:`pdeanim.clip.load_clip`): its
    evaluation tables and coefficients (what a clip cache holds) plus the tangent solve's float64 scratch."""
    knots, values = n_segments + 1, 3 * n_vertices
    held = knots * (values * (10 + 4 * spline) + n_curves * 300)
    solve = knots * min(values, SPLINE_CHUNK) * 24 if spline else 0
    return held + solve


def header_decode_cost(topology: bytes, coefficients: bytes) -> int | None:
    """:func:`decode_cost` of a dynamic-pde clip's parts from their headers (None for another kind)."""
    th, t_shapes = container.shapes(topology)
    ch, c_shapes = container.shapes(coefficients)
    if ch.get("kind") != DynamicClip.kind or "rest" not in t_shapes or "curve_lengths" not in t_shapes:
        return None
    S = ch.get("n_segments")
    S = S if isinstance(S, int) and not isinstance(S, bool) and S > 0 else 1
    return decode_cost(S, int(t_shapes["rest"][0]), int(t_shapes["curve_lengths"][0]))


class BlockedClip:
    """A dynamic-PDE clip's two parts, evaluated block of curves by block: ``evaluate`` gives what
    :meth:`DynamicClip.evaluate` gives, holding one block's decoded clip at a time. Close it (or use it as a
    context manager) to remove its scratch files."""

    kind = DynamicClip.kind

    def __init__(self, topology: bytes, coefficients: bytes, block_bytes: int = BLOCK_BYTES,
                 scratch: str | Path | None = None):
        th, ta = container.unpack(topology)
        self.topo = decode_topology(th, ta)
        self.n_vertices = int(len(self.topo.rest))
        self.faces = self.topo.faces
        self._files: list[IO[bytes]] = []  # unlinked scratch files: closed with the object at the latest
        self._blob = coefficients
        self.header, entries = container.entries(coefficients)
        self._small: dict[str, np.ndarray] = {}
        self._large: dict[str, tuple[IO[bytes], np.dtype, tuple[int, ...]]] = {}
        try:
            for entry in entries:
                self._load(entry, scratch)
        except BaseException:
            self.close()
            raise
        whole = decode_coefficients(self.header, self._block_arrays(0, 0), 0)  # validates the small arrays
        self.frame_times, self.looping = whole.frame_times, whole.looping
        self.segment_t = whole.segment_t
        C, S = self.topo.curves.n_curves, len(self.segment_t) - 1
        lengths = self.topo.curves.lengths
        per_curve = (S + 1) * (lengths * 3 * BYTES_PER_KNOT_VALUE + BYTES_PER_KNOT_CURVE)
        self.bounds = _bounds(np.asarray(per_curve, np.int64), max(int(block_bytes), 1), C)

    def _load(self, entry: tuple, scratch: str | Path | None) -> None:
        """Keep one array: raw ones as views of the blob, small compressed ones decoded, large ones
        decompressed to a scratch file."""
        name, dtype, shape, lo, n, encoding, size = entry
        count = size // dtype.itemsize
        if encoding is None:
            self._small[name] = np.frombuffer(self._blob, dtype=dtype, count=count, offset=lo).reshape(shape)
        elif size <= SPOOL_BYTES or name not in CURVE_AXIS:
            stored = bytes(memoryview(self._blob)[lo:lo + n])
            array = container.decode_array(stored, str(encoding), dtype, count, name)
            self._small[name] = array.reshape(shape)
        else:
            fh = container.spool_array(memoryview(self._blob)[lo:lo + n], str(encoding), dtype, count, name,
                                       None if scratch is None else str(scratch))
            self._files.append(fh)
            self._large[name] = (fh, dtype, shape)

    def _block_arrays(self, c0: int, c1: int) -> dict[str, np.ndarray]:
        """The coefficient arrays of curves c0..c1-1 (per-curve arrays sliced on their curve axis)."""
        out = {}
        for name, a in self._small.items():
            out[name] = _take(a, CURVE_AXIS[name], c0, c1) if name in CURVE_AXIS else a
        for name, (fh, dtype, shape) in self._large.items():
            mm = np.memmap(fh, dtype=dtype, mode="r", shape=shape) if math.prod(shape) else np.empty(
                shape, dtype)
            out[name] = np.array(_take(mm, CURVE_AXIS[name], c0, c1))  # a copy: the mapping ends here
            del mm
        return out

    def block(self, c0: int, c1: int) -> tuple[np.ndarray, DynamicClip]:
        """(vertex indices (Vb,), the decoded clip of curves c0..c1-1 whose vertex i is vertex indices[i])."""
        curves = self.topo.curves
        a, b = int(curves.offsets[c0]), int(curves.offsets[c1])
        idx = np.asarray(curves.order[a:b], np.int64)
        sub = CurveSet(np.arange(b - a, dtype=np.int32), (curves.offsets[c0:c1 + 1] - a).astype(np.int32))
        topo = TopologyData(sub, np.ascontiguousarray(self.topo.u[idx]), np.zeros((0, 3), np.int32),
                            np.ascontiguousarray(self.topo.rest[idx]), self.topo.param_mode)
        coef = decode_coefficients(self.header, self._block_arrays(c0, c1), c1 - c0)
        return idx, DynamicClip(topo, coef, lazy_segments=True)

    def blocks(self) -> Iterator[tuple[np.ndarray, DynamicClip]]:
        """Every block in curve order."""
        for c0, c1 in self.bounds:
            yield self.block(c0, c1)

    def evaluate(self, t: float | np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Positions in the original vertex order, (V, 3) float32 for a scalar t, (K, V, 3) for an array, into
        ``out`` when given (e.g. a memory-mapped file); raises ClipFormatError on non-finite positions."""
        scalar = np.ndim(t) == 0
        times = np.atleast_1d(np.asarray(t, np.float64))
        if out is None:
            out = np.empty((len(times), self.n_vertices, 3), np.float32)
        target = out.reshape(len(times), self.n_vertices, 3)
        with _EVALUATING:
            for idx, clip in self.blocks():
                with np.errstate(all="ignore"):
                    values = clip.evaluate(times)
                del clip
                if not np.all(np.isfinite(values)):
                    raise ClipFormatError("the clip evaluates to non-finite positions")
                target[:, idx] = values
        return target[0] if scalar else out

    def frame_chunks(self, times: np.ndarray, chunk: int, scratch: str | Path | None = None
                     ) -> Iterator[np.ndarray]:
        """The positions at ``times`` (K,) as consecutive (<= chunk, V, 3) float32 blocks of frames in the
        original vertex order: every block of curves is evaluated once into a scratch file (block-major,
        written in sequence), then each block of frames is gathered from it by positioned reads, so neither
        the frames nor a mapping of them is ever held. Raises ClipFormatError on non-finite positions."""
        times = np.atleast_1d(np.asarray(times, np.float64))
        K, chunk = len(times), max(1, int(chunk))
        with tempfile.TemporaryFile(prefix="pdeanim-frames-", dir=scratch) as fh:
            layout = []
            with _EVALUATING:
                for idx, clip in self.blocks():
                    with np.errstate(all="ignore"):
                        values = np.ascontiguousarray(clip.evaluate(times), np.float32)
                    del clip
                    if not np.all(np.isfinite(values)):
                        raise ClipFormatError("the clip evaluates to non-finite positions")
                    layout.append((idx, fh.tell()))
                    fh.write(memoryview(values).cast("B"))
            fh.flush()
            for a in range(0, K, chunk):
                n = min(chunk, K - a)
                out = np.empty((n, self.n_vertices, 3), np.float32)
                for idx, offset in layout:
                    data = os.pread(fh.fileno(), n * len(idx) * 12, offset + a * len(idx) * 12)
                    out[:, idx] = np.frombuffer(data, np.float32).reshape(n, len(idx), 3)
                yield out

    def frame_t(self) -> np.ndarray:
        """(F,) normalised times of the source frames."""
        ft = self.frame_times
        span = ft[-1] - ft[0]
        return (ft - ft[0]) / span if span > 0 else np.zeros_like(ft)

    def info(self) -> dict[str, Any]:
        """JSON-able metadata, as :meth:`DynamicClip.info`."""
        from .clipmodel import _info

        return _info(self.n_vertices, int(len(self.frame_times)), int(len(self.segment_t) - 1),
                     self.topo.curves.n_curves, self.topo.param_mode, self.header,
                     float(self.frame_times[-1] - self.frame_times[0]))

    def close(self) -> None:
        """Close (and so free) the scratch files."""
        for fh in self._files:
            fh.close()
        self._files.clear()

    def __enter__(self) -> BlockedClip:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _take(a: np.ndarray, axis: int, c0: int, c1: int) -> np.ndarray:
    index = [slice(None)] * a.ndim
    index[axis] = slice(c0, c1)
    return a[tuple(index)]


def _bounds(per_curve: np.ndarray, budget: int, C: int) -> list[tuple[int, int]]:
    """Consecutive (c0, c1) blocks of curves whose summed cost stays within ``budget`` (at least a curve)."""
    out, c0, total = [], 0, 0
    for c in range(C):
        if c > c0 and total + int(per_curve[c]) > budget:
            out.append((c0, c))
            c0, total = c, 0
        total += int(per_curve[c])
    if C:
        out.append((c0, C))
    return out
