"""The cyclic job: mesh + mode + parameters -> a looping clip.

Swim modes: body frame (principal axes or head/tail points) -> cross-section curves -> chain of biharmonic
PDE patches -> nearest-point map of every mesh vertex -> spine wave parameters, all packed as a
"cyclic-spine" clip. Gaits (walk, run, trot, pace, canter, gallop, tripod, wave) on a skinned glTF: legs
found from the skeleton -> one locomotion cycle -> a looping fitted "dynamic-pde" clip whose header holds
the travel speed (:mod:`.gaitclip`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from ..clipparts import ClipParts
from ..errors import MeshInputError, ParameterError
from ..progress import Progress, no_progress, sub_progress
from .body import body_frame, cut_body
from .chain import BodySurface, valid_curve_count
from .clipcyclic import make_parts
from .gaits import GAITS, GaitParams
from .pde_surface import MAX_EXPONENT, MIN_A
from .retarget import map_to_surface
from .swim import SwimParams

LIMITS = {"n_curves": (4, 301), "points": (8, 256), "modes": (0, 127), "frames": (2, 10_000)}
"""Inclusive ranges of the integer options."""
GAIT_FRAMES = 2_000
"""Most frames per cycle of a gait (each becomes a fitted pose)."""


@dataclass(frozen=True)
class CyclicOptions:
    """Options of a cyclic job.

    mode: swim preset (eel, trout, tropical, shark, dolphin, or anguilliform, subcarangiform, carangiform,
    thunniform), or a gait of a skinned glTF (walk, run, trot, pace, canter, gallop, tripod, wave);
    overrides: swim parameters replacing the preset's (omega0, omega1, alpha, phi, frequency, amplitude,
    wave, radial), or gait parameters (step_height, step_length, frequency, duty, hip_bob, spine_yaw, ...);
    n_curves: cross-sections (rounded up to 3 B + 1); points: samples per curve; modes: Fourier modes M
    solved exactly; a: PDE smoothing parameter; head, tail, lateral: optional (3,) points/direction fixing
    the body axes; frames: frames per cycle. Gaits only: legs: the foot joints ("foot" or "top:foot"
    names) instead of the legs found; forward: the facing direction instead of the one found; body_joint:
    the joint the body's bob moves instead of the one carrying all legs; target_rel_rms: the fit's error
    target relative to the bounding-box diagonal.
    """

    mode: str = "eel"
    overrides: dict[str, Any] = field(default_factory=dict)
    n_curves: int = 37
    points: int = 32
    modes: int = 6
    a: float = 1.0
    head: tuple[float, float, float] | None = None
    tail: tuple[float, float, float] | None = None
    lateral: tuple[float, float, float] | None = None
    frames: int = 24
    legs: list[str] | None = None
    forward: tuple[float, float, float] | None = None
    body_joint: str | None = None
    target_rel_rms: float = 5e-4

    @staticmethod
    def from_dict(d: dict[str, Any]) -> CyclicOptions:
        """Build from a JSON-like dict; swim parameters may also be given flat. Raises ParameterError."""
        names = {f.name for f in fields(CyclicOptions)}
        swim_names = {f.name for f in fields(SwimParams)} - {"mode"}
        unknown = set(d) - names - swim_names
        if unknown:
            raise ParameterError(f"unknown cyclic option(s): {', '.join(sorted(unknown))}")
        kw = {k: v for k, v in d.items() if k in names}
        over = kw.pop("overrides", None) or {}
        if not isinstance(over, dict):
            raise ParameterError("overrides must be an object of swim parameters")
        over = {**over, **{k: v for k, v in d.items() if k in swim_names}}
        try:
            for k in LIMITS:
                if k in kw:
                    kw[k] = int(kw[k])
            for k in ("a", "target_rel_rms"):
                if k in kw:
                    kw[k] = float(kw[k])
            if kw.get("legs") is not None:
                if isinstance(kw["legs"], str) or not all(isinstance(x, str) for x in kw["legs"]):
                    raise ValueError("legs must be a list of joint names")
                kw["legs"] = list(kw["legs"])
            for k in ("head", "tail", "lateral", "forward"):
                if kw.get(k) is not None:
                    kw[k] = tuple(float(x) for x in kw[k])
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"bad cyclic option value: {exc}") from exc
        opts = CyclicOptions(**kw, overrides=over)
        opts.validate()
        return opts

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict that :meth:`from_dict` reads back."""
        d = asdict(self)
        for k in ("head", "tail", "lateral", "forward"):
            d[k] = list(d[k]) if d[k] is not None else None
        return d

    @property
    def is_gait(self) -> bool:
        """Whether the mode is a gait of a skinned character (else a swim mode)."""
        return self.mode in GAITS

    def swim(self) -> SwimParams:
        """The swim parameters: the preset with the overrides applied."""
        return SwimParams.preset(self.mode, **self.overrides)

    def gait(self) -> GaitParams:
        """The gait parameters: the preset with the overrides applied."""
        return GaitParams.preset(self.mode, **self.overrides)

    def validate(self) -> None:
        """Raise ParameterError for out-of-range values or a bad mode/override."""
        for k, (lo, hi) in LIMITS.items():
            val = getattr(self, k)
            if not lo <= val <= hi:
                raise ParameterError(f"{k} must be in {lo}..{hi}, got {val}")
        if self.modes > (self.points - 1) // 2:
            raise ParameterError(f"modes must be at most (points - 1) // 2 = {(self.points - 1) // 2}")
        if not (np.isfinite(self.a) and MIN_A <= self.a and self.a * (self.modes + 1) <= MAX_EXPONENT):
            raise ParameterError(
                f"a must be >= {MIN_A} with a * (modes + 1) <= {MAX_EXPONENT:g}, got a = {self.a}, "
                f"modes = {self.modes}"
            )
        for k in ("head", "tail", "lateral", "forward"):
            val = getattr(self, k)
            if val is not None and (len(val) != 3 or not np.isfinite(val).all()):
                raise ParameterError(f"{k} must be three finite numbers")
        if not (np.isfinite(self.target_rel_rms) and 1e-6 <= self.target_rel_rms <= 0.1):
            raise ParameterError(f"target_rel_rms must be in 1e-6..0.1, got {self.target_rel_rms}")
        if not self.is_gait:
            self.swim()
            return
        self.gait()
        if self.frames > GAIT_FRAMES:
            raise ParameterError(f"a gait cycle has at most {GAIT_FRAMES} frames, got {self.frames}")
        names_ok = self.legs is None or all(0 < len(x) <= 500 for x in self.legs)
        if self.legs is not None and not (1 <= len(self.legs) <= 64 and names_ok):
            raise ParameterError("legs must name 1 to 64 foot joints (names of 1 to 500 characters)")
        if self.body_joint is not None and not 0 < len(self.body_joint) <= 500:
            raise ParameterError("body_joint must be a joint name of 1 to 500 characters")


def _mesh_arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (T, 3) int64 faces of any object with .vertices and .faces."""
    try:
        verts = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MeshInputError(f"not a triangle mesh: {exc}") from exc
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 4 or not np.isfinite(verts).all():
        raise MeshInputError("the mesh needs at least 4 finite 3D vertices")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshInputError("the mesh has no triangle faces")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise MeshInputError("face indices out of range")
    return verts, faces


def make_gait_clip(source: Any, options: CyclicOptions, progress: Progress | None = None) -> ClipParts:
    """A looping gait clip of the skinned glTF ``source`` (path or bytes): InputError when no legs are
    found or the gait does not fit them, ParameterError on bad options."""
    from .gaitclip import fit_gait_clip, solve_gait

    progress = progress or no_progress
    options.validate()
    progress(0.0, f"cyclic: {options.mode} cycle")
    result = solve_gait(source, options.gait(), options.frames, options.legs, options.forward,
                        options.body_joint)
    progress(0.1, "cyclic: fit the looping clip")
    parts = fit_gait_clip(result, options.target_rel_rms, sub_progress(progress, 0.1, 1.0))
    parts.report["options"] = options.to_dict()
    return parts


def make_cyclic_clip(mesh: Any, options: CyclicOptions, progress: Progress | None = None,
                     source: Any = None) -> ClipParts:
    """A looping swim-cycle clip of an elongated mesh (.vertices (V, 3), .faces (T, 3)), or for a gait mode
    the gait clip of ``source`` (the skinned glTF file's bytes or path the mesh was read from)."""
    options.validate()
    if not options.is_gait:
        return make_swim_clip(mesh, options, progress)
    if source is None:
        raise ParameterError(f"the {options.mode} gait animates a skinned glTF: give its file")
    return make_gait_clip(source, options, progress)


def make_swim_clip(mesh: Any, options: CyclicOptions, progress: Progress | None = None) -> ClipParts:
    """A looping swim-cycle clip of an elongated mesh (.vertices (V, 3), .faces (T, 3)).

    Raises MeshInputError/InputError when the mesh cannot be cut into cross-sections, ParameterError on
    bad options. The report holds curves, patches, the rest-pose distance of the mesh to the PDE surface
    (absolute and relative to the bounding-box diagonal), sizes and timings.
    """
    progress = progress or no_progress
    options.validate()
    params = options.swim()
    verts, faces = _mesh_arrays(mesh)
    t0 = time.perf_counter()
    progress(0.0, "cyclic: body axes")
    # the axis comes from the vertices the faces use: a stray unreferenced vertex must not stretch it
    frame = body_frame(verts[np.unique(faces)], head=options.head, tail=options.tail, lateral=options.lateral)
    n_curves = valid_curve_count(options.n_curves)
    progress(0.1, f"cyclic: cut {n_curves} cross-sections")
    body = cut_body(verts, faces, frame, n_curves, options.points)
    progress(0.4, "cyclic: PDE surface")
    surface = BodySurface.from_curves(body.curves, modes=options.modes, a=options.a)
    t1 = time.perf_counter()
    progress(0.5, "cyclic: map vertices to the surface")
    vmap = map_to_surface(surface, verts, progress=sub_progress(progress, 0.5, 0.95))
    t2 = time.perf_counter()
    diag = float(np.linalg.norm(np.ptp(verts, axis=0)))
    dist = vmap.distance
    settings = {"n_curves": n_curves, "points": options.points, "modes": options.modes, "a": options.a,
                "order": 2}
    report: dict[str, Any] = {
        "kind": "cyclic-spine",
        "curves": n_curves,
        "patches": surface.n_patches,
        "points": options.points,
        "modes": options.modes,
        "multi_loop_slices": int((body.loops > 1).sum()),
        "swim": params.to_dict(),
        "period": params.period,
        "frames": options.frames,
        "body_length": frame.length,
        "diagonal": diag,
        "rest_distance": {
            "mean": float(dist.mean()),
            "max": float(dist.max()),
            "rel_mean": float(dist.mean() / diag),
            "rel_max": float(dist.max() / diag),
        },
        "timings": {"surface_s": t1 - t0, "map_s": t2 - t1},
        "options": options.to_dict(),
    }
    parts = make_parts(
        faces, verts, vmap, surface.spine, body.curves, frame, params, options.frames, settings
    )
    report["sizes"] = parts.sizes(options.frames + 1, len(verts))
    report["mesh_bytes"] = int(verts.astype(np.float32).nbytes + faces.astype(np.int32).nbytes)
    parts.report = report
    progress(1.0, "cyclic: done")
    return parts
