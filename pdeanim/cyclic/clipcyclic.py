"""The "cyclic-spine" clip kind: encode a swim cycle as the two clip parts and evaluate it.

Topology part (static, per mesh and surface settings): faces, rest positions, the per-vertex surface map
(patch, u, v, offset), the boundary curves of the PDE surface and the body frame. Coefficients part (per
clip): the spine polynomials of the patches and the swim-wave parameters. A frame at clip time t in [0, 1]
(one cycle, looping) is rest + the displacement of each vertex's surface point, computed in closed form.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import container
from ..clipparts import FORMAT_VERSION, VALUE_LIMIT, ClipParts, check_format_version, topology_id
from ..errors import ClipFormatError, ParameterError
from .body import BodyFrame
from .retarget import VertexMap
from .spine import Spine
from .swim import SwimParams, body_displacement, lateral_wave

KIND = "cyclic-spine"


def encode_topology(faces: np.ndarray, rest: np.ndarray, vmap: VertexMap, n_patches: int, curves: np.ndarray,
                    frame: BodyFrame, surface_settings: dict[str, Any]) -> bytes:
    """Topology part bytes: faces (T, 3) i32, rest (V, 3) f32, vertex_patch (V,) i32, vertex_uv (V, 2) f32,
    vertex_offset (V, 3) f32, curves (K, P, 3) f32; header with the body frame and surface settings."""
    patch, u = vmap.patch_u(n_patches)
    header = {
        "part": "topology",
        "format_version": FORMAT_VERSION,
        "producer": KIND,
        "n_vertices": int(len(rest)),
        "n_patches": int(n_patches),
        "frame": frame.to_dict(),
        "surface": surface_settings,
    }
    arrays = {
        "faces": np.asarray(faces, dtype=np.int32),
        "rest": np.asarray(rest, dtype=np.float32),
        "vertex_patch": patch.astype(np.int32),
        "vertex_uv": np.stack([u, vmap.v], 1).astype(np.float32),
        "vertex_offset": vmap.offset.astype(np.float32),
        "curves": np.asarray(curves, dtype=np.float32),
    }
    return container.pack(header, arrays)


def encode_coefficients(topology: bytes, spine: Spine, params: SwimParams, frames: int) -> bytes:
    """Coefficients part bytes: spine (B, 2N, 3) f64 and the swim parameters in the header."""
    header = {"part": "coefficients", "format_version": FORMAT_VERSION, "kind": KIND,
              "topology_id": topology_id(topology),
              "swim": params.to_dict(), "period": params.period, "frames": int(frames)}
    return container.pack(header, {"spine": np.asarray(spine.coef, dtype=np.float64)})


class CyclicClip:
    """A looping swim cycle in the :class:`pdeanim.clip.Clip` protocol (t in [0, 1] is one cycle)."""

    kind = KIND
    looping = True

    def __init__(self, faces: np.ndarray, rest: np.ndarray, s: np.ndarray, spine: Spine, frame: BodyFrame,
                 params: SwimParams, frames: int, extra: dict[str, Any] | None = None,
                 curves: np.ndarray | None = None) -> None:
        self.curves = None if curves is None else np.asarray(curves, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int32)
        self.rest = np.asarray(rest, dtype=np.float32)
        self.n_vertices = int(len(self.rest))
        self.spine, self.frame, self.params = spine, frame, params
        self.s = np.asarray(s, dtype=np.float64)
        self.rel = self.rest.astype(np.float64) - spine.at(self.s)
        self.dxds = spine.at(self.s, deriv=1) @ frame.axis
        self.frame_times = np.arange(int(frames) + 1) * (params.period / int(frames))
        self.extra = extra or {}
        self.bend = params.bend_axis(frame.lateral, frame.up)

    def displacement(self, t: float | np.ndarray) -> np.ndarray:
        """Displacement (K, V, 3) float64 at clip times t (K,) (one cycle per unit of t, so t is reduced
        modulo 1 first: a huge t would otherwise overflow the phase and give NaN)."""
        sec = np.mod(np.asarray(t, dtype=np.float64).reshape(-1), 1.0) * self.params.period
        return body_displacement(self.params, self.s, self.rel, self.dxds, self.frame.axis, self.bend,
                                 sec, self.frame.length)

    def evaluate(self, t: float | np.ndarray) -> np.ndarray:
        """Positions: (V, 3) float32 for a scalar t, (K, V, 3) float32 for an array of K times."""
        scalar = np.ndim(t) == 0
        if not np.isfinite(np.asarray(t, dtype=np.float64)).all():
            raise ParameterError("clip times must be finite")
        out = (self.rest[None].astype(np.float64) + self.displacement(t)).astype(np.float32)
        return out[0] if scalar else out

    def surface_frames(
        self, t: float | np.ndarray, n_s: int = 97, n_v: int = 32
    ) -> tuple[np.ndarray, np.ndarray]:
        """The PDE-surface representation itself: grid points (K, n_s n_v, 3) float32 at clip times t (K,)
        moving with the same spine wave, and the grid's faces (T, 3) int32 (the lighter alternative to the
        mesh; rebuilt from the boundary curves of the topology part)."""
        from .chain import BodySurface

        if self.curves is None:
            raise ClipFormatError("this cyclic clip carries no boundary curves")
        settings = self.extra.get("surface", {})
        surface = BodySurface.from_curves(self.curves, modes=int(settings.get("modes", 6)),
                                          a=float(settings.get("a", 1.0)))
        pts, faces = surface.grid_mesh(n_s, n_v)
        s = np.repeat(np.linspace(0.0, 1.0, n_s), n_v)
        rel = pts - self.spine.at(s)
        dxds = self.spine.at(s, deriv=1) @ self.frame.axis
        sec = np.asarray(t, dtype=np.float64).reshape(-1) * self.params.period
        disp = body_displacement(self.params, s, rel, dxds, self.frame.axis, self.bend, sec,
                                 self.frame.length)
        return (pts[None] + disp).astype(np.float32), faces

    def evaluate_seconds(self, seconds: float | np.ndarray) -> np.ndarray:
        """Positions at times in seconds (the cycle repeats every 1 / frequency seconds)."""
        return self.evaluate(np.asarray(seconds, dtype=np.float64) / self.params.period)

    def spine_at(self, t: float, samples: int = 201) -> np.ndarray:
        """The moving spine at clip time t: (samples, 3) float64 (rest spine + lateral wave)."""
        s = np.linspace(0.0, 1.0, samples)
        phase = np.array([np.mod(t, 1.0) * self.params.period])
        delta, _ = lateral_wave(self.params, s, phase, self.frame.length)
        return self.spine.at(s) + delta[0][:, None] * self.bend

    def info(self) -> dict[str, Any]:
        """Frames, period, curves, patches, swim parameters (JSON-able)."""
        return {
            "kind": self.kind,
            "looping": True,
            "vertices": self.n_vertices,
            "faces": int(len(self.faces)),
            "frames": int(len(self.frame_times)),
            "duration": float(self.frame_times[-1]),
            "period": self.params.period,
            "patches": self.spine.n_patches,
            "swim": self.params.to_dict(),
            **self.extra,
        }


MAX_FRAMES = 100_000
"""Most frames a cyclic clip's header may declare (its frame times are allocated from it)."""


def _need(arrays: dict[str, np.ndarray], names: tuple[str, ...], part: str) -> None:
    missing = [n for n in names if n not in arrays]
    if missing:
        raise ClipFormatError(f"cyclic-spine {part} part lacks arrays: {', '.join(missing)}")


def clip_from_parts(th: dict, ta: dict[str, np.ndarray], ch: dict, ca: dict[str, np.ndarray]) -> CyclicClip:
    """Decode both parts (headers and arrays from :func:`pdeanim.container.unpack`) into a CyclicClip."""
    check_format_version(th, "topology")
    check_format_version(ch, "coefficients")
    _need(ta, ("faces", "rest", "vertex_patch", "vertex_uv"), "topology")
    _need(ca, ("spine",), "coefficients")
    try:
        frame = BodyFrame.from_dict(th["frame"])
        params = SwimParams.from_dict(ch["swim"])
        frames = ch.get("frames", 24)
        if not isinstance(frames, int) or isinstance(frames, bool) or not 1 <= frames <= MAX_FRAMES:
            raise ValueError(f"frames must be an integer in 1..{MAX_FRAMES}, got {frames!r}")
    except (KeyError, TypeError, ValueError, ParameterError) as exc:
        raise ClipFormatError(f"bad cyclic-spine clip header: {exc}") from exc
    spine = Spine(np.asarray(ca["spine"], dtype=np.float64))
    patch, uv = np.asarray(ta["vertex_patch"]), np.asarray(ta["vertex_uv"], dtype=np.float64)
    rest, faces = np.asarray(ta["rest"]), np.asarray(ta["faces"])
    V = len(rest)
    shapes_ok = (spine.coef.ndim == 3 and spine.coef.shape[2] == 3 and spine.n_patches >= 1
                 and rest.ndim == 2 and rest.shape[1] == 3 and patch.shape == (V,) and uv.ndim == 2
                 and uv.shape[0] == V and uv.shape[1] >= 1 and faces.ndim == 2 and faces.shape[1] == 3)
    if not shapes_ok:
        raise ClipFormatError("cyclic-spine clip arrays do not fit together")
    patch = patch.astype(np.int64)
    if (V and (patch.min() < 0 or patch.max() >= spine.n_patches)) or (
            faces.size and (faces.min() < 0 or faces.max() >= V)):
        raise ClipFormatError("cyclic-spine clip arrays index outside their range")
    if not (np.all(np.isfinite(spine.coef)) and np.all(np.isfinite(rest)) and np.all(np.isfinite(uv))):
        raise ClipFormatError("cyclic-spine clip arrays hold non-finite values")
    if max(np.abs(spine.coef).max(initial=0.0), np.abs(rest).max(initial=0.0)) > VALUE_LIMIT:
        raise ClipFormatError("cyclic-spine rest or spine holds a value above 2^96 in magnitude (frames "
                              "would not be finite)")
    u = uv[:, 0]
    s = (patch + u) / spine.n_patches
    extra = {
        "curves": int(ta["curves"].shape[0]) if "curves" in ta else None,
        "surface": th.get("surface", {}),
    }
    return CyclicClip(faces, rest, s, spine, frame, params, frames, extra, ta.get("curves"))


def make_parts(faces: np.ndarray, rest: np.ndarray, vmap: VertexMap, spine: Spine, curves: np.ndarray,
               frame: BodyFrame, params: SwimParams, frames: int, surface_settings: dict[str, Any],
               report: dict[str, Any] | None = None) -> ClipParts:
    """Both encoded parts of a cyclic clip as :class:`pdeanim.clip.ClipParts`."""
    topo = encode_topology(faces, rest, vmap, spine.n_patches, curves, frame, surface_settings)
    return ClipParts(topo, encode_coefficients(topo, spine, params, frames), report or {})
