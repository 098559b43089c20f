"""Loading a clip of any kind: the one place that maps a clip's ``kind`` to its evaluator, by plain imports.

The contract every kind implements (:class:`Clip`, :class:`ClipParts`, the CLIP file) is
:mod:`pdeanim.clipparts`, below both producers; this module sits above them. Its names are re-exported here,
so callers import everything about clips from ``pdeanim.clip``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from . import container
from .clipparts import (
    FORMAT_VERSION,
    Clip,
    ClipParts,
    check_format_version,
    read_clip_file,
    topology_id,
    write_clip_file,
)
from .cyclic.clipcyclic import clip_from_parts as cyclic_clip
from .errors import ClipFormatError
from .model.clipmodel import clip_from_parts as dynamic_clip
from .model.clipmodel import header_info as dynamic_info
from .model.streamlayout import is_stream, read_index, stream_info

__all__ = ["FORMAT_VERSION", "Clip", "ClipParts", "check_format_version", "clip_info", "load_clip",
           "load_clip_file", "open_clip",
           "read_clip_file", "topology_id", "write_clip_file"]

DECODERS: dict[str, Callable[[dict[str, Any], dict[str, np.ndarray], dict[str, Any], dict[str, np.ndarray]],
                             Clip]] = {
    "dynamic-pde": dynamic_clip,
    "cyclic-spine": cyclic_clip,
}
"""Clip kind -> decoder of (topology header, topology arrays, coefficients header, coefficients arrays)."""


HEADER_INFO: dict[str, Callable[[bytes, bytes], dict[str, Any]]] = {"dynamic-pde": dynamic_info}
"""Clip kind -> its ``info()`` from the parts' headers (kinds whose decoded size grows with frames x
vertices)."""


def clip_info(topology: bytes, coefficients: bytes) -> dict[str, Any]:
    """``load_clip(...).info()`` without decoding what grows with frames x vertices where the kind allows
    (the metadata of a long clip costs its headers, not its evaluation tables); same checks of the parts."""
    th, _ = container.shapes(topology)
    if is_stream(container.read_header(coefficients)):
        return stream_header_info(topology, coefficients)
    ch, _ = container.shapes(coefficients)
    kind = _check_parts(th, ch, topology)
    if kind in HEADER_INFO:
        return HEADER_INFO[kind](topology, coefficients)
    return load_clip(topology, coefficients).info()


def _check_parts(th: dict[str, Any], ch: dict[str, Any], topology: bytes) -> str:
    """The clip's kind, once the parts' names, versions, topology id and kind are checked."""
    if th.get("part") != "topology":
        raise ClipFormatError(f"expected a topology part, got {th.get('part')!r}")
    if ch.get("part") != "coefficients":
        raise ClipFormatError(f"expected a coefficients part, got {ch.get('part')!r}")
    check_format_version(th, "topology")
    check_format_version(ch, "coefficients")
    want = ch.get("topology_id")
    if want and want != topology_id(topology):
        raise ClipFormatError("the coefficients were made for another topology part (topology_id mismatch)")
    kind = ch.get("kind")
    if kind not in DECODERS:
        raise ClipFormatError(f"unknown clip kind {kind!r} (known: {', '.join(sorted(DECODERS))})")
    return kind


def load_clip(topology: bytes, coefficients: bytes) -> Clip:
    """Decode the two parts into an evaluable Clip; raises ClipFormatError on any mismatch. A streamable
    coefficients part (docs/format.md §3.10) gives a clip that decodes its windows as they are used."""
    th, ta = container.unpack(topology)
    if is_stream(container.read_header(coefficients)):
        from .model.clipformat import decode_topology
        from .model.streamlayout import StreamClip

        ch, _, _ = read_index(coefficients)
        _check_parts(th, ch, topology)
        clip: Clip = StreamClip(decode_topology(th, ta), coefficients)
    else:
        ch, ca = container.unpack(coefficients)
        clip = DECODERS[_check_parts(th, ch, topology)](th, ta, ch, ca)
    with np.errstate(all="ignore"):
        probe = clip.evaluate(np.array([0.0, 0.5, 1.0]))
    if not np.all(np.isfinite(probe)):  # a damaged or hand-made part whose numbers overflow the evaluator
        raise ClipFormatError("the clip evaluates to non-finite positions")
    return clip


def open_clip(topology: bytes, coefficients: bytes, max_decode_bytes: int) -> Clip:
    """The clip of the two parts: decoded whole (:func:`load_clip`) unless decoding it would take more than
    ``max_decode_bytes`` (0: no bound), then evaluated a block of curves at a time in bounded memory
    (:class:`pdeanim.model.clipblocks.BlockedClip`: the same positions, bit for bit, computed per call)."""
    from .model.clipblocks import BlockedClip, header_decode_cost

    if is_stream(container.read_header(coefficients)):  # decoded a few windows at a time anyway
        return load_clip(topology, coefficients)
    cost = header_decode_cost(topology, coefficients) if max_decode_bytes else None
    if cost is None or cost <= max_decode_bytes:
        return load_clip(topology, coefficients)
    th, _ = container.shapes(topology)
    ch, _ = container.shapes(coefficients)
    _check_parts(th, ch, topology)
    return BlockedClip(topology, coefficients)


def stream_header_info(topology: bytes, coefficients: bytes) -> dict[str, Any]:
    """:func:`clip_info` of a streamable part from its header, index and head arrays (no window decoded)."""
    th, t_shapes = container.shapes(topology)
    ch, head, windows = read_index(coefficients)
    _check_parts(th, ch, topology)
    has_times = any(e[0] == "frame_times" for e in head)
    if not has_times or "rest" not in t_shapes or "curve_lengths" not in t_shapes:
        raise ClipFormatError("a dynamic-pde clip needs frame_times, rest and curve_lengths arrays")
    frame_times = container.unpack(coefficients, names=("frame_times",))[1]["frame_times"]
    return stream_info(ch, int(t_shapes["rest"][0]), int(t_shapes["curve_lengths"][0]),
                       str(th.get("param_mode", "chord")), frame_times, windows)


def load_clip_file(path: str | Path) -> Clip:
    """Read and decode a CLIP file."""
    parts = read_clip_file(path)
    return load_clip(parts.topology, parts.coefficients)
