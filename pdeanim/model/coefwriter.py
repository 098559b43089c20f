"""The one writer of the coefficients part (docs/format.md §3.3-3.4): its header keys and arrays, in their
fixed order, from what a fit stores. Every producer calls it (the in-memory encoder, the windowed join), and a
layer of a later minor version (e.g. bones) adds its header keys and arrays through ``extra_header`` and
``extra_arrays``."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..clipparts import FORMAT_VERSION

SPLINE_NEEDS_ZERO_M = "items on the natural spline must have time constant 0 in every segment"

CORE_ARRAYS = ("segment_t", "frame_times", "space_kind", "time_model", "m", "D", "knot_step", "knot_weights",
               "knot_basis", "knots", "knot_windows")
"""Array names of format 1.0's coefficients part, in the order they are stored."""
CORE_HEADER = ("part", "kind", "format_version", "topology_id", "motion", "looping", "n_segments", "n_curves",
               "n_frames", "knot_differences", "knot_rank")
"""Header keys of format 1.0's coefficients part that the writer sets (besides the fit's ``errors``)."""
LAYER_HEADER_KEYS = ("format_version", "required")
"""Core header keys a layer may set: a minor version and the features a reader must know."""


@dataclass
class CoefficientFields:
    """What the coefficients part stores besides the knots: segment boundaries (S+1,) and frame times (F,)
    float64, space kind and time model (C, 3) uint8, signed time constants m (S, C, 3) (< 0 trig, > 0 exp)
    and space constants D (C, 3) float32, the motion mode and whether the clip loops."""

    segment_t: np.ndarray
    frame_times: np.ndarray
    space_kind: np.ndarray
    time_model: np.ndarray
    m: np.ndarray
    D: np.ndarray
    motion: str
    looping: bool


@dataclass
class KnotCodes:
    """The knots as stored: power-of-two steps (C, 3), or (W, C, 3) per window with ``windows`` (W+1,) the
    first knot of each window; zigzag tracks (C, 3, 4, S+1) uint32 of differences of order ``differences``;
    with a shared time basis its zigzag weights (r, C, 3, 4) uint32 and tracks (r, S+1) float32."""

    step: np.ndarray
    tracks: np.ndarray
    differences: int
    weights: np.ndarray | None = None
    basis: np.ndarray | None = None
    windows: np.ndarray | None = None
    shared: bool = False  # weights a windowed fit's windows share (writer only: a window's trial encoding)

    @property
    def rank(self) -> int:
        """How many shared time tracks the knots use (0: plain tracks)."""
        return 0 if self.weights is None else int(self.weights.shape[0])

    def arrays(self) -> dict[str, np.ndarray]:
        """The knot arrays in their stored order."""
        out = {"knot_step": np.asarray(self.step, np.float32)}
        if self.weights is not None:
            out.update(knot_weights=np.asarray(self.weights, np.uint32),
                       knot_basis=np.asarray(self.basis, np.float32))
        out["knots"] = self.tracks
        if self.windows is not None:
            out["knot_windows"] = np.asarray(self.windows, np.uint32)
        return out


def write_coefficients(fields: CoefficientFields, codes: KnotCodes, topo_id: str,
                       header: Mapping[str, Any] | None = None, extra_header: Mapping[str, Any] | None = None,
                       extra_arrays: Mapping[str, np.ndarray] | None = None
                       ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of the coefficients part, before packing. ``header``: keys carried along (the fit's
    ``errors``), overwritten by the part's own; ``extra_header`` and ``extra_arrays``: a layer's additions,
    written last, which may set no key of format 1.0 but ``format_version`` and ``required``."""
    S, C = np.shape(fields.m)[0], np.shape(fields.D)[0]
    time_model = np.asarray(fields.time_model, np.uint8)
    m = np.asarray(fields.m, np.float32)
    if np.any((time_model[None] == 1) & (m != 0)):
        raise ValueError(SPLINE_NEEDS_ZERO_M)
    out = {**(header or {}), "part": "coefficients", "kind": "dynamic-pde", "format_version": FORMAT_VERSION,
           "topology_id": topo_id, "motion": fields.motion, "looping": bool(fields.looping),
           "n_segments": int(S), "n_curves": int(C), "n_frames": int(len(fields.frame_times)),
           "knot_differences": int(codes.differences), "knot_rank": codes.rank}
    clash = set(extra_header or {}) & (set(CORE_HEADER) - set(LAYER_HEADER_KEYS))
    clash |= set(extra_arrays or {}) & set(CORE_ARRAYS)
    if clash:
        raise ValueError(f"a layer may not overwrite the coefficients part's own {sorted(clash)}")
    out.update(extra_header or {})
    seg_t, frame_times = np.asarray(fields.segment_t, np.float64), np.asarray(fields.frame_times, np.float64)
    arrays = {**({} if segment_t_derivable(seg_t, frame_times) else {"segment_t": seg_t}),
              "frame_times": frame_times, "space_kind": np.asarray(fields.space_kind, np.uint8),
              "time_model": time_model, "m": m, "D": np.asarray(fields.D, np.float32), **codes.arrays()}
    arrays.update({k: np.asarray(v) for k, v in (extra_arrays or {}).items()})
    return out, arrays


def frame_segment_t(frame_times: np.ndarray) -> np.ndarray:
    """The segment boundaries of a clip with a knot at every frame: the frame times normalised to [0, 1]
    (docs/format.md §3.3), computed as every reader computes them."""
    ft = np.asarray(frame_times, np.float64)
    return (ft - ft[0]) / (ft[-1] - ft[0])


def segment_t_derivable(seg_t: np.ndarray, frame_times: np.ndarray) -> bool:
    """Whether ``segment_t`` is what readers derive from the frame times, so that it need not be stored."""
    if len(seg_t) != len(frame_times) or len(seg_t) < 2 or not frame_times[-1] > frame_times[0]:
        return False
    return bool(np.array_equal(seg_t, frame_segment_t(frame_times)))
