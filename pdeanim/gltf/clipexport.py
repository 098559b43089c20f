"""GLB of a decoded clip: one frame at normalised time t, or the whole clip sampled at an fps as a
morph-target animation (seamlessly looping for looping clips). Shared by ``pdeanim export``/``frame`` and
the service's frame and animation endpoints."""

from __future__ import annotations

import numpy as np

from ..clip import Clip
from ..errors import LimitError, ParameterError
from ..progress import Progress
from .write import animation_glb, frame_glb

DEFAULT_MAX_FRAMES = 10_000
EVALUATE_CHUNK = 64  # frames evaluated per call when exporting (between progress reports)


def clip_duration(clip: Clip) -> float:
    """Seconds from the clip's first to its last source frame (0 for a single frame)."""
    ft = np.asarray(clip.frame_times, np.float64)
    return float(ft[-1] - ft[0]) if len(ft) > 1 else 0.0


def export_times(duration: float, fps: float, max_frames: int = DEFAULT_MAX_FRAMES) -> np.ndarray:
    """Seconds 0, 1/fps, ... up to ``duration`` with the last instant included: (K,) float64."""
    if not np.isfinite(fps) or fps <= 0:
        raise ParameterError(f"fps must be a positive number, got {fps}")
    if duration <= 0:
        return np.zeros(1)
    n = int(np.floor(duration * fps + 1e-6)) + 1
    if n + 1 > max_frames:
        raise LimitError("exported frame count", n + 1, max_frames)
    t = np.arange(n) / fps
    if duration - t[-1] > 1e-6 * duration:
        t = np.append(t, duration)
    return t


def clip_animation_glb(clip: Clip, fps: float = 30.0, *, quantize: bool = False,
                       max_frames: int = DEFAULT_MAX_FRAMES, progress: Progress | None = None) -> bytes:
    """The clip as an animated GLB: frames evaluated at ``fps`` over its duration, last frame included; for a
    looping clip the last key is the first frame exactly, so playback wraps without a seam. Frames are
    evaluated in chunks so ``progress`` hears about long exports."""
    duration = clip_duration(clip)
    seconds = export_times(duration, fps, max_frames)
    t = seconds / duration if duration > 0 else seconds
    frames = np.empty((len(t), clip.n_vertices, 3), np.float32)
    for lo in range(0, len(t), EVALUATE_CHUNK):
        hi = min(lo + EVALUATE_CHUNK, len(t))
        frames[lo:hi] = np.asarray(clip.evaluate(t[lo:hi]), np.float32).reshape(hi - lo, -1, 3)
        if progress is not None:
            progress(0.9 * hi / len(t), f"evaluate {hi}/{len(t)}")
    loop = bool(clip.looping) and len(t) > 1
    if loop:
        frames[-1] = frames[0]  # period 1 in t: the end of the cycle is its start
    names = [f"t{x:.4f}" for x in t]
    glb = animation_glb(frames, seconds, clip.faces, quantize=quantize, loop=loop, names=names)
    if progress is not None:
        progress(1.0, "write GLB")
    return glb


def clip_frame_glb(clip: Clip, t: float) -> bytes:
    """One frame of the clip at normalised time t as GLB (positions, normals, original faces)."""
    if not np.isfinite(t):
        raise ParameterError(f"t must be a finite number, got {t}")
    return frame_glb(np.asarray(clip.evaluate(float(t)), np.float32).reshape(-1, 3), clip.faces)
