"""The clip contract: what every producer (dynamic-PDE fit, cyclic PDE surfaces) hands to every consumer
(CLI, service, glTF export), independent of how it was made. Producers import this module; the loader that
dispatches on a clip's kind (:mod:`pdeanim.clip`) sits above them.

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
    faces: np.ndarray  # (T, 3) int32, the mesh's triangles (dynamic-pde: in a canonical order)
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


VALUE_LIMIT = 2.0**96
"""Largest magnitude of a position-scale number a reader accepts (docs/format.md §5): rest coordinates, knots,
rigid centres and translations, cyclic rest positions and spine coefficients. With the space basis at most 2
and the time weights below 2^25, no frame of such a clip overflows float32 (2^128)."""
FORMAT_VERSION = "1.0"
"""The clip format every part and CLIP file is written in (docs/format.md). Readers accept any "1.<minor>":
minor versions only add header keys or arrays that a reader may ignore; a new major version is refused."""


SUPPORTED_FEATURES = ("bones", "stream")
"""Features of minor versions this reader implements; a part whose ``required`` lists another is refused
(docs/format.md §2). "bones" (1.1, §3.9) and "stream" (1.2, §3.10, the streamable layout) are read by the
dynamic-PDE kind only."""
FEATURE_KINDS = {"bones": ("dynamic-pde",), "stream": ("dynamic-pde",)}


def check_format_version(header: dict[str, Any], part: str) -> None:
    """Raise ClipFormatError unless the header's ``format_version`` is "1.<minor>" (see FORMAT_VERSION) and
    this reader implements every feature its ``required`` lists."""
    version = header.get("format_version")
    major, _, minor = version.partition(".") if isinstance(version, str) else ("", "", "")
    if major != FORMAT_VERSION.partition(".")[0] or not minor.isdigit() or not minor.isascii():
        raise ClipFormatError(f"unsupported clip format version {version!r} in the {part} part "
                              f"(this build reads {FORMAT_VERSION.partition('.')[0]}.x)")
    check_required(header, part)


def check_required(header: dict[str, Any], part: str) -> None:
    """Raise ClipFormatError unless ``required`` (absent: none) is a list of feature names that this reader
    implements for the part's kind."""
    required = header.get("required", [])
    if not isinstance(required, list) or not all(isinstance(name, str) for name in required):
        raise ClipFormatError(f"the {part} part's 'required' must be a list of feature names, "
                              f"got {required!r}")
    missing = sorted(set(required) - set(SUPPORTED_FEATURES))
    if missing:
        supported = ", ".join(SUPPORTED_FEATURES)
        raise ClipFormatError(f"the {part} part requires feature(s) {', '.join(map(repr, missing))} that "
                              f"this reader does not implement (it supports: {supported})")
    kind = header.get("kind")
    for name in required:
        if kind is not None and kind not in FEATURE_KINDS.get(name, (kind,)):
            raise ClipFormatError(f"the {part} part of kind {kind!r} requires feature {name!r}, which only "
                                  f"kind(s) {', '.join(FEATURE_KINDS[name])} implement")


def write_clip_file(path: str | Path, parts: ClipParts) -> None:
    """Write both parts into one CLIP file."""
    header = {"part": "clip-file", "format_version": FORMAT_VERSION, "topology_id": parts.topology_id,
              "report": parts.report}
    coef = container.read_header(parts.coefficients)
    if coef.get("required"):  # a feature of a minor version (the bone layer, 1.1): the file says so too
        header.update(format_version=coef["format_version"], required=coef["required"])
    blob = container.pack(header,
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
    check_format_version(header, "clip-file")
    return ClipParts(arrays["topology"].tobytes(), arrays["coefficients"].tobytes(), header.get("report", {}))
