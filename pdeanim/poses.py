"""Poses: F frames of the same mesh (same vertex count, same faces), the input of the fit.

On disk a POSES.npz holds ``vertices`` (F, V, 3) float32, ``faces`` (T, 3) int32 and optionally ``times``
(F,) float seconds (default: 0, 1/30, ...). Animated glTF files are read by :mod:`pdeanim.gltf`.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import LimitError, PosesInputError
from .npzread import ArrayHeader, read_npz

DEFAULT_FPS = 30.0


@dataclass(frozen=True)
class PoseLimits:
    """Explicit limits on what a poses input may hold."""

    max_frames: int = 10_000
    max_vertices: int = 2_000_000
    max_values: int = 400_000_000  # frames * vertices * 3
    max_bytes: int = 2 * 1024**3  # all arrays of a .npz once inflated


@dataclass
class Poses:
    """A sequence of frames of one mesh.

    vertices : (F, V, 3) float32 positions per frame, in the original vertex order
    faces : (T, 3) int32 triangle indices into V (may be empty for point data)
    times : (F,) float64 strictly increasing seconds
    meta : free-form provenance (source file, simulation parameters, reports)
    rest : (V, 3) the rest pose a fit stores and measures displacements from (None: the first frame); a
        bone layer's residual is fitted about the pose its bones skin
    """

    vertices: np.ndarray
    faces: np.ndarray
    times: np.ndarray
    meta: dict = field(default_factory=dict)
    rest: np.ndarray | None = None

    def rest_pose(self) -> np.ndarray:
        """(V, 3) the rest pose: ``rest`` where given, else the first frame."""
        return self.vertices[0] if self.rest is None else self.rest

    @property
    def n_frames(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[1])

    def validate(self, limits: PoseLimits | None = None) -> Poses:
        """Check shapes, finiteness, index ranges and limits; returns self or raises PosesInputError."""
        validate_pose_arrays(self.vertices, self.faces, self.times, limits)
        return self


def make_poses(vertices: np.ndarray, faces: np.ndarray | None, times: np.ndarray | None = None,
               meta: dict | None = None, limits: PoseLimits | None = None) -> Poses:
    """Build validated Poses with canonical dtypes; ``times`` defaults to 30 fps from 0."""
    v = np.asarray(vertices)
    if v.ndim == 2 and v.shape[-1] == 3:
        v = v[None]
    if v.ndim != 3 or v.shape[-1] != 3:
        raise PosesInputError(f"vertices must have shape (F, V, 3), got {v.shape}")
    f = np.zeros((0, 3), np.int32) if faces is None else np.asarray(faces)
    if times is None:
        times = np.arange(v.shape[0], dtype=np.float64) / DEFAULT_FPS
    validate_pose_arrays(v, f, np.asarray(times), limits)
    return Poses(v.astype(np.float32, copy=False), f.astype(np.int32, copy=False),
                 np.asarray(times, dtype=np.float64), dict(meta or {}))


def validate_pose_arrays(vertices: np.ndarray, faces: np.ndarray, times: np.ndarray,
                         limits: PoseLimits | None = None, values_checked: bool = False) -> None:
    """Raise PosesInputError (or LimitError) naming the first problem found (``values_checked``: the vertices'
    values were already found finite, e.g. chunk by chunk as they were read)."""
    limits = limits or PoseLimits()
    if vertices.ndim != 3 or vertices.shape[-1] != 3:
        raise PosesInputError(f"vertices must have shape (F, V, 3), got {vertices.shape}")
    n_frames, n_verts = vertices.shape[:2]
    if n_frames < 1 or n_verts < 1:
        raise PosesInputError(f"poses need at least one frame and one vertex, got {vertices.shape}")
    if n_frames > limits.max_frames:
        raise LimitError("frame count", n_frames, limits.max_frames, "PDEANIM_MAX_FRAMES")
    if n_verts > limits.max_vertices:
        raise LimitError("vertex count", n_verts, limits.max_vertices, "PDEANIM_MAX_VERTICES")
    if vertices.size > limits.max_values:
        raise LimitError("frames x vertices x 3", vertices.size, limits.max_values)
    if vertices.dtype.kind not in "fiu":
        raise PosesInputError(f"vertices must be real numbers, got dtype {vertices.dtype}")
    if not values_checked and not np.all(np.isfinite(vertices)):
        bad = np.argwhere(~np.isfinite(vertices))[0]
        raise PosesInputError(
            f"vertices contain NaN or infinite values (first at frame {bad[0]}, vertex {bad[1]})"
        )
    if faces.ndim != 2 or (faces.size and faces.shape[1] != 3):
        raise PosesInputError(f"faces must have shape (T, 3), got {faces.shape}")
    if faces.size:
        if not np.issubdtype(faces.dtype, np.integer):
            raise PosesInputError(f"faces must be integer indices, got dtype {faces.dtype}")
        if faces.min() < 0 or faces.max() >= n_verts:
            raise PosesInputError(
                f"face indices must lie in [0, {n_verts}), found {faces.min()}..{faces.max()}"
            )
    if times.shape != (n_frames,):
        raise PosesInputError(f"times must have shape ({n_frames},), got {times.shape}")
    if times.dtype.kind not in "fiu":
        raise PosesInputError(f"times must be real numbers, got dtype {times.dtype}")
    if not np.all(np.isfinite(times)):
        raise PosesInputError("times contain NaN or infinite values")
    if n_frames > 1 and not np.all(np.diff(times) > 0):
        raise PosesInputError("times must be strictly increasing")


def check_npz_headers(headers: dict[str, ArrayHeader], limits: PoseLimits) -> None:
    """Refuse a POSES.npz from its npy headers alone (before inflating): shapes, dtypes and limits."""
    if "vertices" not in headers:
        raise PosesInputError("poses .npz has no 'vertices' array")
    kinds = {"vertices": "fiu", "faces": "iu", "times": "fiu"}
    for name, head in headers.items():
        if head.dtype.kind not in kinds[name]:
            raise PosesInputError(f"{name} must be {'integers' if name == 'faces' else 'real numbers'}, "
                                  f"got dtype {head.dtype}")
    v = headers["vertices"].shape
    if len(v) not in (2, 3) or v[-1] != 3:
        raise PosesInputError(f"vertices must have shape (F, V, 3), got {v}")
    frames, verts = (1, v[0]) if len(v) == 2 else v[:2]
    if frames > limits.max_frames:
        raise LimitError("frame count", frames, limits.max_frames, "PDEANIM_MAX_FRAMES")
    if verts > limits.max_vertices:
        raise LimitError("vertex count", verts, limits.max_vertices, "PDEANIM_MAX_VERTICES")
    if headers["vertices"].count > limits.max_values:
        raise LimitError("frames x vertices x 3", headers["vertices"].count, limits.max_values)
    if "times" in headers and headers["times"].count > limits.max_frames:
        raise LimitError("times count", headers["times"].count, limits.max_frames, "PDEANIM_MAX_FRAMES")
    if "faces" in headers and headers["faces"].count > limits.max_values:
        raise LimitError("faces x 3", headers["faces"].count, limits.max_values)
    total = sum(head.nbytes for head in headers.values())
    if total > limits.max_bytes:
        raise LimitError("inflated size of the .npz arrays in bytes", total, limits.max_bytes,
                         "PDEANIM_MAX_POSE_BYTES")


def load_poses_npz(source: str | Path | bytes, limits: PoseLimits | None = None) -> Poses:
    """Read a POSES.npz (path or bytes): ``vertices`` (F,V,3), ``faces`` (T,3), optional ``times`` (F,).

    Headers are checked against ``limits`` before any array is inflated (bounded memory on hostile files).
    """
    limits = limits or PoseLimits()
    data = read_npz(source, ("vertices", "faces", "times"), lambda h: check_npz_headers(h, limits),
                    PosesInputError)
    return make_poses(data["vertices"], data.get("faces"), data.get("times"), {"source": "npz"}, limits)


def load_poses_npz_mapped(path: str | Path, limits: PoseLimits | None = None,
                          tmp_dir: str | None = None, into: Path | None = None) -> Poses | None:
    """:func:`load_poses_npz` of a file, its vertices (F, V, 3) float32 mapped from a file instead of held in
    memory (:func:`pdeanim.npzread.mapped_member`: the .npz itself where they are stored uncompressed as
    float32, else a temporary file they are inflated into), for fits that read the frames a window at a time
    (:mod:`pdeanim.fit.windowed` drops each window's pages once done). Falls back to :func:`load_poses_npz`
    where the vertices cannot be mapped (a single frame, Fortran order); with ``into`` (the vertices written
    to that file as raw float32, see :func:`pdeanim.npzread.mapped_member`) None there instead."""
    from .npzread import mapped_member

    limits = limits or PoseLimits()
    headers: dict = {}

    def check(found: dict) -> None:
        check_npz_headers(found, limits)
        headers.update(found)

    small = read_npz(path, ("vertices", "faces", "times"), check, PosesInputError, skip=("vertices",))

    def finite(values: np.ndarray, first: int) -> None:
        if not np.all(np.isfinite(values)):
            at = (first + int(np.argmin(np.isfinite(values)))) // 3
            n_verts = int(np.prod(headers["vertices"].shape[1:-1]))
            raise PosesInputError(f"vertices contain NaN or infinite values (first at frame {at // n_verts}, "
                                  f"vertex {at % n_verts})")

    vertices = mapped_member(path, "vertices", finite, PosesInputError, tmp_dir, into)
    if vertices is None:
        return None if into is not None else load_poses_npz(path, limits)
    f = small.get("faces")
    f = np.zeros((0, 3), np.int32) if f is None else np.asarray(f)
    times = small.get("times")
    times = np.arange(vertices.shape[0], dtype=np.float64) / DEFAULT_FPS if times is None else times
    validate_pose_arrays(vertices, f, np.asarray(times), limits, values_checked=True)
    return Poses(vertices, f.astype(np.int32, copy=False), np.asarray(times, dtype=np.float64),
                 {"source": "npz"})


def save_poses(path: str | Path, poses: Poses) -> None:
    """Write POSES.npz (the bytes of :func:`poses_to_bytes`), streamed to the file (no copy in memory)."""
    with open(path, "wb") as fh:
        _write_npz(fh, poses)


def poses_to_bytes(poses: Poses) -> bytes:
    """The POSES.npz file as bytes, float32 vertices, int32 faces and float64 times (what
    ``GET /v1/poses/{id}`` serves and ``pdeanim simulate`` writes)."""
    buf = io.BytesIO()
    _write_npz(buf, poses)
    return buf.getvalue()


def _write_npz(fh: io.IOBase, poses: Poses) -> None:
    """POSES.npz into a binary file object (arrays already in their canonical dtypes are not copied)."""
    np.savez_compressed(fh, vertices=poses.vertices.astype(np.float32, copy=False),
                        faces=poses.faces.astype(np.int32, copy=False),
                        times=poses.times.astype(np.float64, copy=False))
