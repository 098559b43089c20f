"""Spine-driven swimming: a periodic lateral wave on the spine, the radial part of the body carried along.

The spine is displaced sideways by
    Delta(s, t) = A L W(s) cos(alpha U + phi) sin(2 pi omega t),   U = 2 pi s,  W(s) = Omega(U) / peak,
with Omega(U) = omega0 + omega1 U / (2 pi) (the amplitude law of the swim-mode table), s in [0, 1] from head
to
tail, L the body length, A the peak displacement as a fraction of L (the table's Omega is in the units of the
authors' models, so its shape is kept and its peak normalised), t in seconds. With wave = "travelling" the
factor cos(alpha U + phi) sin(2 pi omega t) becomes sin(2 pi omega t - alpha U - phi), a wave running from
head
to tail. The wave moves the spine along the body's lateral axis, or along its up axis with
direction = "vertical" (the dorso-ventral beat of dolphins and whales). Every point keeps its offset from the
spine ("translate", as in the paper) or has it turned with the
local bend of the spine ("rotate", so cross-sections stay square to the spine). Both repeat with period
1/omega.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from ..errors import ParameterError

PRESETS: dict[str, dict[str, float]] = {
    "eel": {"omega0": 0.0, "omega1": 0.3, "alpha": 1.5, "phi": np.pi / 2, "frequency": 1.0},
    "trout": {"omega0": 0.0, "omega1": 1.0, "alpha": 0.75, "phi": np.pi / 2, "frequency": 2.0},
    "tropical": {"omega0": 0.1, "omega1": 0.0, "alpha": 1.0, "phi": np.pi / 2, "frequency": 2.0},
    "shark": {"omega0": 0.0, "omega1": 1.0, "alpha": 0.25, "phi": 0.0, "frequency": 1.0},
    "dolphin": {"omega0": 1.0, "omega1": 0.0, "alpha": 0.75, "phi": np.pi / 2, "frequency": 1.3},
}
"""The swim-mode table: amplitude law Omega(U) = omega0 + omega1 U / 2pi, wave number, phase, frequency."""

ALIASES = {"anguilliform": "eel", "subcarangiform": "trout", "carangiform": "tropical", "thunniform": "shark"}
"""Locomotion class names mapped to the preset of their representative fish."""

WAVES = ("standing", "travelling")
RADIAL = ("rotate", "translate")
DIRECTIONS = ("lateral", "vertical")


@dataclass(frozen=True)
class SwimParams:
    """Parameters of the spine wave (see the module docstring); amplitude is a fraction of body length."""

    mode: str = "eel"
    omega0: float = 0.0
    omega1: float = 0.3
    alpha: float = 1.5
    phi: float = float(np.pi / 2)
    frequency: float = 1.0
    amplitude: float = 0.08
    wave: str = "standing"
    radial: str = "rotate"
    direction: str = "lateral"

    def bend_axis(self, lateral: np.ndarray, up: np.ndarray) -> np.ndarray:
        """The direction (3,) the spine moves in: the body's lateral or up axis."""
        return np.asarray(up if self.direction == "vertical" else lateral, dtype=np.float64)

    @staticmethod
    def preset(mode: str, **overrides: Any) -> SwimParams:
        """The named preset (eel, trout, tropical, shark, dolphin or a locomotion class) with overrides."""
        key = ALIASES.get(str(mode).lower(), str(mode).lower())
        if key not in PRESETS:
            known = ", ".join([*PRESETS, *ALIASES])
            raise ParameterError(f"unknown swim mode {mode!r} (known: {known})")
        return SwimParams.from_dict({**PRESETS[key], **overrides, "mode": key})

    @staticmethod
    def from_dict(d: dict[str, Any]) -> SwimParams:
        """Build and validate from a dict; unknown keys or bad values raise ParameterError."""
        names = {f.name for f in fields(SwimParams)}
        unknown = set(d) - names
        if unknown:
            raise ParameterError(f"unknown swim parameter(s): {', '.join(sorted(unknown))}")
        try:
            vals = {
                k: (str(v) if k in ("mode", "wave", "radial", "direction") else float(v))
                for k, v in d.items()
            }
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"bad swim parameter value: {exc}") from exc
        params = replace(SwimParams(), **vals)
        params.validate()
        return params

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict that :meth:`from_dict` reads back."""
        return asdict(self)

    def validate(self) -> None:
        """Raise ParameterError on non-finite numbers, a frequency <= 0 or an unknown wave/radial kind."""
        nums = [self.omega0, self.omega1, self.alpha, self.phi, self.frequency, self.amplitude]
        if not np.isfinite(nums).all():
            raise ParameterError("swim parameters must be finite numbers")
        if not 1e-3 <= self.frequency <= 1e3:
            raise ParameterError(f"frequency must lie in [0.001, 1000] cycles per second, got "
                                 f"{self.frequency}")
        if not 0 <= self.amplitude <= 1:
            raise ParameterError(
                f"amplitude is a fraction of the body length in [0, 1], got {self.amplitude}"
            )
        if self.wave not in WAVES or self.radial not in RADIAL or self.direction not in DIRECTIONS:
            raise ParameterError(f"wave must be one of {WAVES}, radial one of {RADIAL}, direction one of "
                                 f"{DIRECTIONS}")

    @property
    def period(self) -> float:
        """Seconds per cycle, 1 / omega."""
        return 1.0 / self.frequency

    def peak(self) -> float:
        """Peak of |Omega(U) cos(alpha U + phi)| over the body (dense sample), the normaliser of W."""
        s = np.linspace(0.0, 1.0, 2049)
        shape = (self.omega0 + self.omega1 * s) * (np.cos(2 * np.pi * self.alpha * s + self.phi)
                                                   if self.wave == "standing" else 1.0)
        return float(np.abs(shape).max())


def lateral_wave(
    params: SwimParams, s: np.ndarray, t: np.ndarray, length: float
) -> tuple[np.ndarray, np.ndarray]:
    """Spine displacement Delta (K, V) and its slope dDelta/ds (K, V) at s (V,) for times t (K,) seconds."""
    s = np.asarray(s, dtype=np.float64)[None, :]
    t = np.asarray(t, dtype=np.float64).reshape(-1)[:, None]
    peak = params.peak()
    gain = params.amplitude * length / peak if peak > 0 else 0.0
    amp = params.omega0 + params.omega1 * s
    k = 2 * np.pi * params.alpha
    wt = 2 * np.pi * params.frequency * t
    if params.wave == "standing":
        space, dspace = np.cos(k * s + params.phi), -k * np.sin(k * s + params.phi)
        delta = amp * space * np.sin(wt)
        slope = (params.omega1 * space + amp * dspace) * np.sin(wt)
    else:
        arg = wt - k * s - params.phi
        delta = amp * np.sin(arg)
        slope = params.omega1 * np.sin(arg) - amp * k * np.cos(arg)
    return gain * delta, gain * slope


def body_displacement(params: SwimParams, s: np.ndarray, rel: np.ndarray, dxds: np.ndarray, axis: np.ndarray,
                      lateral: np.ndarray, t: np.ndarray, length: float) -> np.ndarray:
    """Displacement (K, V, 3) of points at chain parameter s (V,) for times t (K,) seconds.

    rel (V, 3): each point minus its spine point at rest; dxds (V,): rate of the spine's axial coordinate
    along s; axis, lateral (3,): body axes. The spine moves by Delta along lateral; with radial = "rotate"
    rel also turns in the axis-lateral plane by atan(dDelta/dx) (dx/ds floored at 0.1 L where the spine
    folds).
    """
    delta, slope = lateral_wave(params, s, t, length)
    disp = delta[..., None] * lateral
    if params.radial == "rotate":
        g = slope / np.maximum(np.asarray(dxds, dtype=np.float64), 0.1 * length)[None, :]  # spine folds
        c = 1.0 / np.sqrt(1.0 + g * g)
        sn = g * c
        ra, rl = rel @ axis, rel @ lateral
        disp = (
            disp
            + ((c - 1.0) * ra - sn * rl)[..., None] * axis
            + (sn * ra + (c - 1.0) * rl)[..., None] * lateral
        )
    return disp
