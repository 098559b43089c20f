"""GLB of a decoded clip: one frame at normalised time t, or the whole clip sampled at an fps as a
morph-target animation (seamlessly looping for looping clips), small by default (quantised + meshopt, see
:mod:`.compact`) and keeping the source mesh's look when a :class:`~.layout.Layout` of it is given. Shared by
``pdeanim export``/``frame``, the service's frame and animation routes and its ``export`` jobs."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from ..clipparts import Clip
from ..errors import LimitError, ParameterError
from ..progress import Progress
from .compact import PackOptions, layout_animation_glb, layout_frame_glb
from .layout import Layout, plain_layout
from .skinexport import has_bone_layer, skinned_animation_glb
from .write import _check_times, _key_plan, animation_glb, frame_glb

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
        raise LimitError("exported frame count", n + 1, max_frames,
                         "max_frames (PDEANIM_MAX_FRAMES in the service)")
    t = np.arange(n) / fps
    if duration - t[-1] > 1e-6 * duration:
        t = np.append(t, duration)
    return t


@dataclass(frozen=True)
class ExportEstimate:
    """What an animation export will hold before it is built: sampled frames, morph targets, and the bytes
    of those frames as raw float32 positions (the work and memory building it takes scale with them)."""

    frames: int
    targets: int
    vertices: int
    raw_frame_bytes: int

    def to_dict(self) -> dict[str, int]:
        """JSON-ready fields."""
        return {"frames": self.frames, "targets": self.targets, "vertices": self.vertices,
                "raw_frame_bytes": self.raw_frame_bytes}


EXPORT_PACK = PackOptions(normals=False, position_bits=None)
"""How clip exports are packed unless told otherwise: without per-frame normal targets, which cost 35-40% of
a smooth mesh's GLB (every frame then carries the first frame's normals; a receiver that shades deforming
meshes recomputes them from the positions). ``normals=True`` (``--normal-targets``) keeps them. The position
grid follows the clip's own error (:func:`export_position_error`); ``position_bits`` sets it by hand."""

QUANT_SHARE = 0.25
"""The position grid of a clip export may add an RMS distance of this share of the clip's own RMS error (the
fit's, stored in the clip): in quadrature that is at most 3% more RMS error than the clip has, and the
grid's largest rounding (step * sqrt(3) / 2) is 0.43 of the clip's RMS error. On the benchmark's clips fitted
at the default target that is a step of 0.66-1.6e-3 of the animation's extent (9-11 bits of it, against the
14 bits every export had before)."""


def export_position_error(clip: Clip) -> float | None:
    """The RMS distance the export's position grid may add: QUANT_SHARE of the clip's RMS error as its fit
    measured it (``info()["errors"]["rms"]``); None when the clip does not say (then 14 bits)."""
    try:
        rms = clip.info().get("errors", {}).get("rms")
    except (AttributeError, TypeError):
        return None
    if isinstance(rms, bool) or not isinstance(rms, (int, float)) or not math.isfinite(rms) or rms <= 0:
        return None
    return QUANT_SHARE * float(rms)


@dataclass(frozen=True)
class ExportOptions:
    """Options of an animation export (the service's ``export`` job): ``fps`` and how it is packed
    (``position_bits`` None: the grid follows the clip's own error, see EXPORT_PACK)."""

    fps: float = 30.0
    quantize: bool = True
    compress: bool = True
    position_bits: int | None = None
    normals: bool = False

    @staticmethod
    def from_dict(d: dict[str, Any]) -> ExportOptions:
        """Build from a JSON-like dict; ParameterError on unknown keys or bad values."""
        names = {f.name for f in fields(ExportOptions)}
        unknown = set(d) - names
        if unknown:
            raise ParameterError(f"unknown export option(s): {', '.join(sorted(unknown))}")
        kw = dict(d)
        try:
            if "fps" in kw:
                kw["fps"] = float(kw["fps"])
            if kw.get("position_bits") is not None:
                bits = kw["position_bits"]
                if isinstance(bits, bool) or float(bits) != int(bits):
                    raise ValueError("position_bits must be an integer")
                kw["position_bits"] = int(kw["position_bits"])
        except (TypeError, ValueError, OverflowError) as exc:
            raise ParameterError(f"bad export option: {exc}") from exc
        for k in ("quantize", "compress", "normals"):
            if k in kw and not isinstance(kw[k], bool):
                raise ParameterError(f"{k} must be true or false, got {kw[k]!r}")
        opts = ExportOptions(**kw)
        if not np.isfinite(opts.fps) or opts.fps <= 0:
            raise ParameterError(f"fps must be a positive number, got {opts.fps}")
        opts.pack()  # checks position_bits
        return opts

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict that :meth:`from_dict` reads back."""
        return asdict(self)

    def pack(self) -> PackOptions:
        """The packing part of the options."""
        return PackOptions(self.quantize, self.compress, self.position_bits, self.normals)


def estimate_export(clip: Clip, fps: float, max_frames: int = DEFAULT_MAX_FRAMES) -> ExportEstimate:
    """Frames, morph targets and raw float32 frame bytes of ``clip_animation_glb(clip, fps)``, cheaply."""
    k = len(export_times(clip_duration(clip), fps, max_frames))
    targets = k - 1 if bool(clip.looping) and k > 1 else k
    return ExportEstimate(k, targets, int(clip.n_vertices), int(k * clip.n_vertices * 12))


def clip_animation_glb(clip: Clip, fps: float = 30.0, *, options: PackOptions | None = None,
                       layout: Layout | None = None, max_frames: int = DEFAULT_MAX_FRAMES,
                       progress: Progress | None = None) -> bytes:
    """The clip as an animated GLB: frames evaluated at ``fps`` over its duration, last frame included; for a
    looping clip the last key is the first frame exactly, so playback wraps without a seam. ``options``
    default to EXPORT_PACK (quantised on a grid that adds at most QUANT_SHARE of the clip's own RMS error,
    meshopt-compressed, welded, no normal targets); ``layout`` (default
    plain) keeps a source mesh's look. ``PackOptions(quantize=False, compress=False, weld=False)``
    writes the plain float32 layout of :func:`~.write.animation_glb`. Frames are evaluated in chunks so
    ``progress`` hears about long exports. A clip with a bone layer (format 1.1) and no source look
    (``layout`` None or plain) is written as a skinned animation (:mod:`.skinexport`: joints, skin, morph
    targets only for a non-zero residual; float32, not quantised or compressed); with a source look its
    frames are baked into morph targets as for any clip."""
    opts = options or EXPORT_PACK
    if opts.quantize and opts.position_bits is None and opts.position_error is None:
        opts = replace(opts, position_error=export_position_error(clip))
    duration = clip_duration(clip)
    seconds = export_times(duration, fps, max_frames)
    t = seconds / duration if duration > 0 else seconds
    if has_bone_layer(clip) and (layout is None or layout.source == "plain"):
        glb = skinned_animation_glb(clip, seconds, t, normals=opts.normals, names=[f"t{x:.4f}" for x in t])
        if progress is not None:
            progress(1.0, "write GLB")
        return glb
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
    if layout is None and not (opts.quantize or opts.compress or opts.weld):
        glb = animation_glb(frames, seconds, clip.faces, loop=loop, names=names, normals=opts.normals)
    else:
        lay = layout or plain_layout(clip.faces, clip.n_vertices)
        t32 = _check_times(seconds, len(frames))
        key_times, key_target, n_targets = _key_plan(frames, t32, loop)
        glb = layout_animation_glb(lay, frames, key_times, key_target, n_targets, options=opts,
                                   names=names[:n_targets], loop=loop)
    if progress is not None:
        progress(1.0, "write GLB")
    return glb


def clip_frame_glb(clip: Clip, t: float, layout: Layout | None = None) -> bytes:
    """One frame of the clip at normalised time t as GLB (positions, normals, original faces; the source's
    look when ``layout`` is given)."""
    if not np.isfinite(t):
        raise ParameterError(f"t must be a finite number, got {t}")
    positions = np.asarray(clip.evaluate(float(t)), np.float32).reshape(-1, 3)
    if layout is None:
        return frame_glb(positions, clip.faces)
    return layout_frame_glb(layout, positions)
