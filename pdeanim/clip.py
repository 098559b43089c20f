"""The clip: what every producer (dynamic-PDE fit, cyclic PDE surfaces) hands to every consumer
(CLI, service, glTF export), independent of how it was made.

A clip has two parts, both pdeanim containers (:mod:`pdeanim.container`):

* the **topology** (static) part, once per mesh/curve layout: ``header["part"] == "topology"``;
  vertex order, faces, rest positions and whatever per-vertex parametrisation the producer needs;
* the **coefficients** (per-clip) part: ``header["part"] == "coefficients"``, ``header["kind"]`` names the
  producer (``"dynamic-pde"`` or ``"cyclic-spine"``), and ``header["topology_id"]`` is the SHA-256 hex of
  the topology part's bytes, so a client can tell which static part it needs.

A CLIP file on disk (``pdeanim fit --out CLIP``) is one container with ``part == "clip-file"`` holding the
two parts as uint8 arrays ``topology`` and ``coefficients``.
"""

from __future__ import annotations

import hashlib
import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from . import container
from .errors import ClipFormatError


@runtime_checkable
class Clip(Protocol):
    """A decoded clip that evaluates vertex positions at normalised time t in [0, 1].

    t = 0 and t = 1 map to the first and last source frame times (``frame_times``); looping clips repeat
    with period 1 in t.
    """

    kind: str
    n_vertices: int
    faces: np.ndarray  # (T, 3) int32, the mesh's triangles (version 2 parts: in a canonical order)
    frame_times: np.ndarray  # (F,) float64 seconds of the source frames
    looping: bool

    def evaluate(self, t: float | np.ndarray) -> np.ndarray:
        """Positions in the original vertex order: (V, 3) float32 for scalar t, (K, V, 3) for an array."""
        ...

    def info(self) -> dict[str, Any]:
        """JSON-able metadata: frames, segments, curves, byte sizes, errors achieved."""
        ...


@dataclass
class ClipParts:
    """The two encoded parts of a clip plus the producer's report (errors, timings, sizes)."""

    topology: bytes
    coefficients: bytes
    report: dict[str, Any] = field(default_factory=dict)

    @property
    def topology_id(self) -> str:
        return topology_id(self.topology)

    def sizes(self, n_frames: int, n_vertices: int) -> dict[str, int | float]:
        """Honest size accounting: bytes of each part against raw float32 positions of all frames."""
        raw = int(n_frames) * int(n_vertices) * 3 * 4
        total = len(self.topology) + len(self.coefficients)
        return {
            "topology_bytes": len(self.topology),
            "coefficients_bytes": len(self.coefficients),
            "raw_float32_bytes": raw,
            "ratio_coefficients_to_raw": len(self.coefficients) / raw if raw else 0.0,
            "ratio_total_to_raw": total / raw if raw else 0.0,
        }


def topology_id(topology: bytes) -> str:
    """Content id of a topology part: SHA-256 hex of its bytes."""
    return hashlib.sha256(topology).hexdigest()


# kind -> "module:callable" taking (topology_header, topology_arrays, coeff_header, coeff_arrays) -> Clip
LOADERS: dict[str, str] = {
    "dynamic-pde": "pdeanim.model.clipmodel:clip_from_parts",
    "cyclic-spine": "pdeanim.cyclic.clipcyclic:clip_from_parts",
}


def _loader(kind: str) -> Callable[..., Clip]:
    if kind not in LOADERS:
        raise ClipFormatError(f"unknown clip kind {kind!r} (known: {', '.join(sorted(LOADERS))})")
    module, _, name = LOADERS[kind].partition(":")
    return getattr(importlib.import_module(module), name)


def load_clip(topology: bytes, coefficients: bytes) -> Clip:
    """Decode the two parts into an evaluable Clip; raises ClipFormatError on any mismatch."""
    th, ta = container.unpack(topology)
    ch, ca = container.unpack(coefficients)
    if th.get("part") != "topology":
        raise ClipFormatError(f"expected a topology part, got {th.get('part')!r}")
    if ch.get("part") != "coefficients":
        raise ClipFormatError(f"expected a coefficients part, got {ch.get('part')!r}")
    want = ch.get("topology_id")
    if want and want != topology_id(topology):
        raise ClipFormatError("the coefficients were made for another topology part (topology_id mismatch)")
    clip = _loader(str(ch.get("kind")))(th, ta, ch, ca)
    with np.errstate(all="ignore"):
        probe = clip.evaluate(np.array([0.0, 0.5, 1.0]))
    if not np.all(np.isfinite(probe)):  # a damaged or hand-made part whose numbers overflow the evaluator
        raise ClipFormatError("the clip evaluates to non-finite positions")
    return clip


def write_clip_file(path: str | Path, parts: ClipParts) -> None:
    """Write both parts into one CLIP file."""
    blob = container.pack({"part": "clip-file", "topology_id": parts.topology_id, "report": parts.report},
                          {"topology": np.frombuffer(parts.topology, np.uint8),
                           "coefficients": np.frombuffer(parts.coefficients, np.uint8)})
    Path(path).write_bytes(blob)


def read_clip_file(path: str | Path) -> ClipParts:
    """Read a CLIP file written by :func:`write_clip_file`."""
    try:
        blob = Path(path).read_bytes()
    except OSError as exc:
        raise ClipFormatError(f"cannot read clip file {path}: {exc}") from exc
    header, arrays = container.unpack(blob)
    if header.get("part") != "clip-file" or not {"topology", "coefficients"} <= arrays.keys():
        raise ClipFormatError(f"{path} is not a pdeanim CLIP file")
    return ClipParts(arrays["topology"].tobytes(), arrays["coefficients"].tobytes(), header.get("report", {}))


def load_clip_file(path: str | Path) -> Clip:
    """Read and decode a CLIP file."""
    parts = read_clip_file(path)
    return load_clip(parts.topology, parts.coefficients)
