"""Scene parameters of a simulation job: timing, material, forces, pins, rigid drivers and a ground plane.

Regions (for pins and drivers) are dicts with one of
``{"indices": [...]}`` (surface vertex indices), ``{"box": [xmin, ymin, zmin, xmax, ymax, zmax]}`` or
``{"plane": [px, py, pz, nx, ny, nz]}`` (the side (x - p) . n <= 0), plus ``"relative": true`` to give points
as fractions of the rest bounding box. A driver is ``{"region": REGION, "keyframes": [{"t": 0..1,
"rotate": [ax, ay, az, degrees], "translate": [x, y, z]}, ...], "center": [x, y, z] (default: region
centroid)}``
with t normalised over the clip; rotations are slerped and translations lerped between keyframes. The solver
has no randomness (the same mesh, tets and parameters give the same poses), so there is no ``seed``: one given
by an older client is accepted and ignored.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

from ..errors import LimitError, ParameterError

REGION_KINDS = ("indices", "box", "plane")
MAX_REGIONS = 256
"""At most this many pins and this many drivers: regions are tested against every tet point."""
MAX_KEYFRAMES = 1000
MAX_INDICES = 2_000_000
MAX_TET_SWEEPS = 5e9
"""Refuse a simulation needing more than this many tet updates (frames x substeps x iterations x tets): about
a quarter of an hour single-threaded at the measured ~0.17 us per tet and sweep."""
MAX_GRAVITY = 1e6
"""Largest gravity magnitude (mesh units per s^2): 100 g for a mesh in millimetres. Past it the automatic
stiffness and substeps overflow (gravity [1e308, 1e308, 1e308] failed with ZeroDivisionError)."""
MAX_YOUNG = 1e15  # Pa: a thousand times diamond's
MAX_DENSITY = 1e9  # mass per unit volume of the mesh's units: far past any material's 2.3e4 kg/m^3
MAX_DAMPING = 1e6  # 1/s
IGNORED_KEYS = ("seed",)
"""Keys older clients sent that no longer mean anything; accepted (if well-typed) and dropped."""


@dataclass
class SceneParams:
    """Everything that defines a simulation besides the mesh; ``from_dict``/``to_dict`` for jobs and
    records."""

    frames: int = 100
    fps: float = 30.0
    duration: float | None = None
    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    damping: float = 1.0
    young: float | None = None  # None: chosen from the mesh's size (pdeanim.sim.simulate.auto_young)
    poisson: float = 0.3
    density: float = 1000.0
    pins: list[dict] = field(default_factory=list)
    drivers: list[dict] = field(default_factory=list)
    ground: dict | None = None
    target_tets: int = 3000
    substeps: int | None = None
    max_substeps: int = 400
    iterations: int = 1
    threads: int = 1

    def __post_init__(self) -> None:
        self.validate()

    @classmethod
    def from_dict(cls, d: dict | None) -> SceneParams:
        """Build from a JSON-like dict; ParameterError names unknown keys and bad values."""
        d = dict(d or {})
        for key in IGNORED_KEYS:
            if key in d and not (isinstance(d[key], int) and not isinstance(d[key], bool)):
                raise ParameterError(f"{key} must be an integer (it is ignored: the simulation is "
                                     "deterministic)")
            d.pop(key, None)
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ParameterError(f"unknown scene parameter(s) {unknown}; known: {sorted(known)}")
        try:
            return cls(**d)
        except TypeError as exc:
            raise ParameterError(f"bad scene parameters: {exc}") from exc

    def to_dict(self) -> dict:
        """A JSON-ready dict that ``from_dict`` turns back into an equal SceneParams."""
        out = asdict(self)
        out["gravity"] = list(self.gravity)
        return out

    def work(self, substeps: int | None = None) -> float:
        """Tet updates the simulation may need: (frames - 1) x substeps x iterations x target_tets, with
        ``substeps`` the actual count, or the most the scene allows (explicit substeps, else max_substeps).

        The API checks this bound at submission and the simulator checks it with the substeps it chose (never
        more than the bound), so a job accepted at submission is never refused later for its work."""
        steps = substeps or self.substeps or self.max_substeps
        return float(max(self.frames - 1, 0)) * steps * self.iterations * self.target_tets

    def check_work(self, substeps: int | None = None) -> None:
        """LimitError (HTTP 413) naming what to lower when :meth:`work` is over MAX_TET_SWEEPS."""
        work = self.work(substeps)
        if work > MAX_TET_SWEEPS:
            bound = "" if substeps or self.substeps else ", with substeps up to max_substeps"
            exc = LimitError(f"simulation work (frames x substeps x iterations x target_tets{bound})",
                             int(work), int(MAX_TET_SWEEPS))
            exc.args = (f"{exc}: lower frames, substeps or max_substeps, iterations or target_tets",)
            raise exc

    def frame_times(self):
        """(frames,) float64 seconds of the output frames, from 0."""
        import numpy as np

        step = self.duration / max(self.frames - 1, 1) if self.duration is not None else 1.0 / self.fps
        return np.arange(self.frames, dtype=np.float64) * step

    def validate(self) -> None:
        """Raise ParameterError for the first out-of-range or inconsistent value."""
        self.gravity = vector(self.gravity, 3, "gravity")
        if math.hypot(*self.gravity) > MAX_GRAVITY:
            raise ParameterError(f"gravity must have a magnitude of at most {MAX_GRAVITY:g} (mesh units per "
                                 f"s^2), got {math.hypot(*self.gravity):g}")
        checks = [
            (
                isinstance(self.frames, int) and 1 <= self.frames <= 10_000,
                "frames must be an integer in [1, 10000]",
            ),
            (number(self.fps) and 0 < self.fps <= 10_000, "fps must be in (0, 10000]"),
            (self.duration is None or (number(self.duration) and self.duration > 0), "duration must be > 0"),
            (number(self.damping) and 0 <= self.damping <= MAX_DAMPING,
             f"damping must be in [0, {MAX_DAMPING:g}] (1/s)"),
            (self.young is None or (number(self.young) and 0 < self.young <= MAX_YOUNG),
             f"young (Young's modulus, Pa) must be in (0, {MAX_YOUNG:g}], or null to choose it from the "
             "mesh's size"),
            (number(self.poisson) and 0 <= self.poisson < 0.5, "poisson must be in [0, 0.5)"),
            (number(self.density) and 0 < self.density <= MAX_DENSITY,
             f"density must be in (0, {MAX_DENSITY:g}]"),
            (
                isinstance(self.target_tets, int) and 50 <= self.target_tets <= 2_000_000,
                "target_tets must be an integer in [50, 2000000]",
            ),
            (
                self.substeps is None or (isinstance(self.substeps, int) and 1 <= self.substeps <= 10_000),
                "substeps must be null (automatic) or an integer in [1, 10000]",
            ),
            (
                isinstance(self.max_substeps, int) and 1 <= self.max_substeps <= 10_000,
                "max_substeps in [1, 10000]",
            ),
            (
                isinstance(self.iterations, int) and 1 <= self.iterations <= 100,
                "iterations must be in [1, 100]",
            ),
            (isinstance(self.threads, int) and 1 <= self.threads <= 256, "threads must be in [1, 256]"),
            (
                isinstance(self.pins, list) and isinstance(self.drivers, list),
                "pins and drivers must be lists",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise ParameterError(message)
        if len(self.pins) > MAX_REGIONS or len(self.drivers) > MAX_REGIONS:
            raise ParameterError(
                f"at most {MAX_REGIONS} pins and {MAX_REGIONS} drivers, got "
                f"{len(self.pins)} pins and {len(self.drivers)} drivers (merge regions: a box "
                "or plane covers many)"
            )
        for region in self.pins:
            validate_region(region, "pin")
        for driver in self.drivers:
            validate_driver(driver)
        if self.ground is not None:
            validate_ground(self.ground)


def number(value: object) -> bool:
    """True for a finite int or float (not bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def vector(value: object, n: int, name: str) -> tuple[float, ...]:
    """A tuple of n finite floats, or ParameterError."""
    if not isinstance(value, list | tuple) or len(value) != n or not all(number(v) for v in value):
        raise ParameterError(f"{name} must be {n} finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


def validate_region(region: object, what: str) -> None:
    """Check a region dict (exactly one of indices, box, plane; optional relative)."""
    if not isinstance(region, dict):
        raise ParameterError(f"{what} region must be an object, got {region!r}")
    kinds = [k for k in REGION_KINDS if k in region]
    extra = sorted(set(region) - set(REGION_KINDS) - {"relative"})
    if len(kinds) != 1 or extra:
        raise ParameterError(f"{what} region needs exactly one of {REGION_KINDS} (and optional 'relative'), "
                             f"got keys {sorted(region)}")
    kind = kinds[0]
    if kind == "indices":
        idx = region["indices"]
        if isinstance(idx, list) and len(idx) > MAX_INDICES:
            raise ParameterError(f"{what} indices: at most {MAX_INDICES}, got {len(idx)}")
        if not isinstance(idx, list) or not idx or not all(isinstance(i, int) and i >= 0 for i in idx):
            raise ParameterError(f"{what} indices must be a non-empty list of vertex indices >= 0")
    elif kind == "box":
        box = vector(region["box"], 6, f"{what} box")
        if any(box[i] > box[i + 3] for i in range(3)):
            raise ParameterError(f"{what} box needs min <= max on every axis, got {list(box)}")
    else:
        plane = vector(region["plane"], 6, f"{what} plane")
        if all(v == 0 for v in plane[3:]):
            raise ParameterError(f"{what} plane normal must not be zero")
    if not isinstance(region.get("relative", False), bool):
        raise ParameterError(f"{what} 'relative' must be true or false")


def validate_driver(driver: object) -> None:
    """Check a driver dict: a region and at least one keyframe with t in [0, 1], increasing."""
    if not isinstance(driver, dict) or "region" not in driver or "keyframes" not in driver:
        raise ParameterError("a driver needs 'region' and 'keyframes'")
    extra = sorted(set(driver) - {"region", "keyframes", "center"})
    if extra:
        raise ParameterError(f"unknown driver key(s) {extra}")
    validate_region(driver["region"], "driver")
    if "center" in driver:
        vector(driver["center"], 3, "driver center")
    keys = driver["keyframes"]
    if not isinstance(keys, list) or not keys or len(keys) > MAX_KEYFRAMES:
        raise ParameterError(f"driver keyframes must be a non-empty list of at most {MAX_KEYFRAMES}")
    times = []
    for key in keys:
        if not isinstance(key, dict) or set(key) - {"t", "rotate", "translate"} or not number(key.get("t")):
            raise ParameterError(
                f"a keyframe is {{'t', 'rotate', 'translate'}} with t in [0, 1], got {key!r}"
            )
        if "rotate" in key:
            rot = vector(key["rotate"], 4, "keyframe rotate")
            if all(v == 0 for v in rot[:3]):
                raise ParameterError("keyframe rotation axis must not be zero")
        if "translate" in key:
            vector(key["translate"], 3, "keyframe translate")
        times.append(float(key["t"]))
    if any(t < 0 or t > 1 for t in times) or any(b <= a for a, b in zip(times, times[1:], strict=False)):
        raise ParameterError(f"keyframe times must increase within [0, 1], got {times}")


def validate_ground(ground: object) -> None:
    """Check a ground dict: point, normal (non-zero), optional friction in [0, 1]."""
    if not isinstance(ground, dict) or set(ground) - {"point", "normal", "friction"}:
        raise ParameterError("ground must be {'point': [x, y, z], 'normal': [x, y, z], 'friction': 0..1}")
    vector(ground.get("point", (0.0, 0.0, 0.0)), 3, "ground point")
    normal = vector(ground.get("normal", (0.0, 1.0, 0.0)), 3, "ground normal")
    if all(v == 0 for v in normal):
        raise ParameterError("ground normal must not be zero")
    friction = ground.get("friction", 0.0)
    if not number(friction) or not 0 <= friction <= 1:
        raise ParameterError("ground friction must be in [0, 1]")
