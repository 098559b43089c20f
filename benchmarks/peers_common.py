"""Shared parts of the compression benchmark (benchmarks/compression_peers.py): progress lines, zstd, uniform
quantisation, the file format of the array peers, faces coded for them, result rows and the k search."""

from __future__ import annotations

import json
import os
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

OMP_WAIT_POLICY = os.environ.setdefault("OMP_WAIT_POLICY", "passive")
"""OpenMP threads (Dem Bones', and any the fits load) sleep instead of spinning while they wait: on a shared,
loaded machine spinning threads made a Dem Bones solve 30x slower (89 s against 2.9 s for the 384-vertex tube
at load 20). Set before any OpenMP runtime loads; the fits' child processes inherit it."""

ROOT = Path(__file__).resolve().parent.parent
CODE = Path(os.environ.get("PDEANIM_CODE") or ROOT).resolve()
"""The tree whose ``pdeanim`` is measured: $PDEANIM_CODE (e.g. ``git archive COMMIT | tar -x -C DIR`` of
another commit, to measure its clip with this benchmark) or this checkout. The clip fits run it and every
score uses its metrics; $PDEANIM_CODE_LABEL names it in the tables when it is not a git checkout."""
if str(CODE) not in sys.path:
    sys.path.insert(0, str(CODE))


def code_label() -> str:
    """The measured code: its short commit (marked when pdeanim/ has local changes) or $PDEANIM_CODE_LABEL."""
    import subprocess

    if os.environ.get("PDEANIM_CODE_LABEL"):
        return os.environ["PDEANIM_CODE_LABEL"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=CODE, capture_output=True,
                            text=True).stdout.strip()
    if not commit or not (CODE / ".git").exists():
        return f"unlabelled tree {CODE}" if CODE != ROOT else "unknown"
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "pdeanim"], cwd=CODE, capture_output=True,
                           text=True).stdout.strip()
    return f"commit {commit}{' (pdeanim/ modified)' if dirty else ''}"

from pdeanim.model.metrics import error_summary  # noqa: E402

FPS = 30.0
WIRE_LEVEL = 19  # "on the wire": every file zstd -19, as an HTTP content coding


def log(msg: str) -> None:
    """Progress line on stderr with the 1-min load average."""
    print(f"[{time.strftime('%H:%M:%S')} load {os.getloadavg()[0]:.1f}] {msg}", file=sys.stderr, flush=True)


def zstd19(blob: bytes | np.ndarray) -> bytes:
    """zstd -19 of a byte string (an array by its raw bytes)."""
    import zstandard

    raw = blob.tobytes() if isinstance(blob, np.ndarray) else bytes(blob)
    return zstandard.ZstdCompressor(level=WIRE_LEVEL).compress(raw)


def wire_bytes(file_bytes: bytes) -> int:
    """Bytes of a file on the wire: its zstd -19 content coding (the clip's parts included)."""
    return len(zstd19(file_bytes))


def quantise(a: np.ndarray, axis: tuple[int, ...] | int | None, bits: int) -> tuple[np.ndarray, np.ndarray,
                                                                                    np.ndarray]:
    """Uniform ``bits``-bit quantisation with a [min, max] range over ``axis`` (kept dims): (codes,
    dequantised float64, ranges float32 (2, ...) that a decoder needs)."""
    a = np.asarray(a, np.float64)
    lo = a.min(axis=axis, keepdims=True).astype(np.float32).astype(np.float64)
    hi = a.max(axis=axis, keepdims=True).astype(np.float32).astype(np.float64)
    scale = np.where(hi > lo, (hi - lo) / (2**bits - 1), 1.0)
    q = np.clip(np.rint((a - lo) / scale), 0, 2**bits - 1).astype(np.uint16 if bits <= 16 else np.uint32)
    return q, lo + q * scale, np.stack([lo, hi]).astype(np.float32)


def pack_payload(kind: str, arrays: dict[str, np.ndarray]) -> bytes:
    """A peer's file: a JSON header (kind, each array's name, dtype and shape) then every array as its own
    zstd -19 frame (the arrays' codes differ, so separate frames compress them better than one stream)."""
    head = {"kind": kind, "arrays": [[k, str(v.dtype), list(v.shape)] for k, v in arrays.items()]}
    js = json.dumps(head, separators=(",", ":")).encode()
    parts = [struct.pack("<I", len(js)), js]
    for v in arrays.values():
        z = zstd19(np.ascontiguousarray(v))
        parts += [struct.pack("<I", len(z)), z]
    return b"".join(parts)


def faces_code(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """The faces as the array peers ship them: triangles reordered for the vertex cache and coded with
    meshoptimizer's index codec (a few bits per triangle); vertex order unchanged."""
    import meshoptimizer

    idx = np.ascontiguousarray(np.asarray(faces, np.uint32).reshape(-1))
    opt = np.empty_like(idx)
    meshoptimizer.optimize_vertex_cache(opt, idx, len(idx), n_vertices)
    return np.frombuffer(meshoptimizer.encode_index_buffer(opt, len(opt), n_vertices), np.uint8)


def result(method: str, setting: str, file_bytes: bytes | int, approx: np.ndarray | None, X: np.ndarray,
           wire: int | None = None, **extra) -> dict:
    """One result row: file and wire bytes and the errors of ``approx`` against the source frames X."""
    size = file_bytes if isinstance(file_bytes, int) else len(file_bytes)
    if wire is None:
        wire = wire_bytes(file_bytes) if not isinstance(file_bytes, int) else size
    err = error_summary(X, approx) if approx is not None else extra.pop("errors")
    return {"method": method, "setting": setting, "file_bytes": int(size), "wire_bytes": int(wire),
            "rel_rms": err["rel_rms"], "rel_max": err["rel_max"], "kg": err["kg"], **extra}


def smallest_meeting(lo: int, hi: int, meets: Callable[[int], bool]) -> int | None:
    """The smallest n in [lo, hi] with meets(n), by bisection (meets is taken as monotone: once an n meets
    the target every larger one does); None if hi does not meet it."""
    if not meets(hi):
        return None
    while lo < hi:
        mid = (lo + hi) // 2
        if meets(mid):
            hi = mid
        else:
            lo = mid + 1
    return lo


class WeldedInput:
    """An input with its seam duplicates merged (vertices whose positions agree in every frame, as a glTF
    export leaves them at UV and normal seams): the array peers fit the P distinct trajectories and ship the
    vertex -> point remap (counted in their bytes) to give every vertex its point's motion back."""

    def __init__(self, X: np.ndarray, faces: np.ndarray) -> None:
        from pdeanim.bones.trajweld import weld_trajectories

        w = weld_trajectories(X.astype(np.float32))
        self.point_of = w.point_of
        self.merged = w.n_points < X.shape[1]
        self.X = X[:, w.keep]
        f = self.point_of[np.asarray(faces, np.int64)]
        keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
        self.faces = f[keep].astype(np.int32)

    def arrays(self) -> dict[str, np.ndarray]:
        """The remap as a file holds it (differences of consecutive point ids, int32), none when nothing
        merged."""
        if not self.merged:
            return {}
        return {"remap": np.diff(self.point_of, prepend=0).astype(np.int32)}

    def expand(self, approx: np.ndarray) -> np.ndarray:
        """Decoded frames of the points (F, P, 3) -> of every vertex (F, V, 3)."""
        return approx if not self.merged else approx[:, self.point_of]
