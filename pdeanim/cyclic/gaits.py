"""Gaits: which legs step when (the footfall phase of each leg and the duty factor, the share of the cycle a
foot is on the ground) and the preset sizes of each gait.

Two legs: walk and run. Four legs: walk (lateral sequence: hind-left, fore-left, hind-right, fore-right a
quarter cycle apart), trot (diagonal pairs together), pace (same-side pairs together), canter (three beats)
and gallop (four beats, transverse). Six or more: tripod (alternating tripods, or tetrapods on eight legs)
and wave (one leg at a time, back to front on each side); on four legs the wave gait is the walk.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from ..errors import ParameterError
from .legs import Leg

BOUNCING = ("run", "trot", "pace", "canter", "gallop", "tripod")
"""Gaits whose body sinks at mid-stance (spring-like legs); the others vault over a stiff stance leg."""

PRESETS: dict[str, dict[str, float]] = {
    "walk": {"step_height": 0.12, "step_length": 0.3, "frequency": 1.0, "hip_bob": 0.03},
    "run": {"step_height": 0.3, "step_length": 0.55, "frequency": 1.6, "hip_bob": 0.07},
    "trot": {"step_height": 0.18, "step_length": 0.3, "frequency": 1.8, "hip_bob": 0.04},
    "pace": {"step_height": 0.15, "step_length": 0.3, "frequency": 1.6, "hip_bob": 0.03},
    "canter": {"step_height": 0.2, "step_length": 0.35, "frequency": 1.8, "hip_bob": 0.05,
               "spine_flex": 0.12},
    "gallop": {"step_height": 0.25, "step_length": 0.4, "frequency": 2.4, "hip_bob": 0.06,
               "spine_flex": 0.25},
    "tripod": {"step_height": 0.15, "step_length": 0.2, "frequency": 2.0, "hip_bob": 0.01},
    "wave": {"step_height": 0.12, "step_length": 0.2, "frequency": 1.2, "hip_bob": 0.005},
}
"""Gait presets; heights, lengths and the bob are fractions of the mean leg length."""

GAITS = tuple(PRESETS)

DUTY = {"walk": 0.6, "run": 0.4, "trot": 0.5, "pace": 0.5, "canter": 0.4, "gallop": 0.3, "tripod": 0.5}
"""Default duty factors (the wave gait and the walk on four or more legs: 1 - 1 / legs)."""

QUAD_PHASES = {  # footfall phase by (row, side): row 0 front, 1 hind; side +1 left, -1 right
    "trot": {(0, 1): 0.0, (1, -1): 0.0, (0, -1): 0.5, (1, 1): 0.5},
    "pace": {(0, 1): 0.0, (1, 1): 0.0, (0, -1): 0.5, (1, -1): 0.5},
    "canter": {(1, -1): 0.0, (1, 1): 0.3, (0, -1): 0.3, (0, 1): 0.6},
    "gallop": {(1, -1): 0.0, (1, 1): 0.1, (0, -1): 0.4, (0, 1): 0.5},
}


@dataclass(frozen=True)
class GaitParams:
    """Gait parameters: step_height H and step_length L (half the stride; fractions of the mean leg
    length), frequency f (cycles per second), duty (stance share; None = the gait's), the per-side fine
    tuning of Eq. 10 (height_right H_R, lift_right H_RF, length_right L_R and their left twins; fractions of
    the leg length), hip_bob (fraction of the leg length), hip_sway (sideways, the same), body_pitch (1 =
    the body follows the height of each row of legs), spine_yaw (radians a girdle turns at full stride),
    spine_flex (radians the back arches when the hind feet reach forward and the fore feet back),
    head_level (share of the body's turn and pitch the neck undoes), tail_sway (the tail turns against the
    hips by this multiple of their turn: 1 keeps it straight behind, 2 swings it the other way),
    heel_strike and toe_off (radians a plantigrade foot is pitched toes up as its heel lands and heel up as
    it pushes off about the ball), literal
    (Eq. 10 as printed: sinusoidal paths, both feet lifted by sin(2 pi f t))."""

    gait: str = "walk"
    step_height: float = 0.12
    step_length: float = 0.3
    frequency: float = 1.0
    duty: float | None = None
    height_right: float = 0.0
    height_left: float = 0.0
    lift_right: float = 0.0
    lift_left: float = 0.0
    length_right: float = 0.0
    length_left: float = 0.0
    hip_bob: float = 0.03
    hip_sway: float = 0.0
    body_pitch: float = 1.0
    spine_yaw: float = 0.08
    spine_flex: float = 0.0
    head_level: float = 1.0
    tail_sway: float = 2.0
    heel_strike: float = 0.25
    toe_off: float = 0.25
    literal: bool = False

    @staticmethod
    def preset(gait: str, **overrides: Any) -> GaitParams:
        """The gait's preset with overrides; raises ParameterError on unknown names or bad values."""
        if gait not in PRESETS:
            raise ParameterError(f"unknown gait {gait!r} (known: {', '.join(GAITS)})")
        names = {f.name for f in fields(GaitParams)} - {"gait"}
        unknown = set(overrides) - names
        if unknown:
            raise ParameterError(f"unknown gait parameter(s): {', '.join(sorted(unknown))} "
                                 f"(known: {', '.join(sorted(names))})")
        vals: dict[str, Any] = {}
        try:
            for k, v in {**PRESETS[gait], **overrides}.items():
                if k == "literal":
                    vals[k] = _flag(v)
                elif k == "duty":
                    vals[k] = None if v is None else float(v)
                else:
                    vals[k] = float(v)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"bad gait parameter value: {exc}") from exc
        return replace(GaitParams(), gait=gait, **vals).validate()

    def validate(self) -> GaitParams:
        """Raise ParameterError on a non-finite value, a frequency <= 0 or a duty outside (0, 1)."""
        nums = [getattr(self, f.name) for f in fields(self) if f.name not in ("gait", "literal", "duty")]
        if not np.isfinite(nums).all() or self.frequency <= 0 or self.frequency > 100:
            raise ParameterError("gait parameters must be finite and the frequency in (0, 100]")
        if self.duty is not None and not (np.isfinite(self.duty) and 0.05 <= self.duty <= 0.95):
            raise ParameterError(f"duty must be in 0.05..0.95, got {self.duty}")
        if self.step_length < 0 or self.step_height < 0:
            raise ParameterError("step_length and step_height must be >= 0")
        return self

    @property
    def period(self) -> float:
        """Seconds per cycle."""
        return 1.0 / self.frequency

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict of the parameters."""
        return asdict(self)


def _flag(v: Any) -> bool:
    if isinstance(v, str):
        if v.strip().lower() not in ("1", "0", "true", "false", "yes", "no"):
            raise ValueError(f"literal must be true or false, got {v!r}")
        return v.strip().lower() in ("1", "true", "yes")
    if not isinstance(v, bool | int):
        raise TypeError(f"literal must be true or false, got {v!r}")
    return bool(v)


def _need(gait: str, legs: list[Leg], ok: bool, what: str) -> None:
    if not ok:
        found = ", ".join(leg.name for leg in legs)
        raise ParameterError(f"the {gait} gait needs {what}; found {len(legs)} legs ({found})")


def _paired(legs: list[Leg]) -> bool:
    rows = max(leg.row for leg in legs) + 1
    return all(sorted(leg.side for leg in legs if leg.row == r) == [-1, 1] for r in range(rows))


def leg_phases(gait: str, legs: list[Leg], duty: float | None = None) -> tuple[np.ndarray, float]:
    """Footfall phase in [0, 1) of every leg (n,) and the duty factor; ParameterError when the gait does not
    fit the legs (e.g. a trot on six legs)."""
    n, rows = len(legs), max(leg.row for leg in legs) + 1
    paired = _paired(legs)
    if gait in ("walk", "run") and rows == 1:
        _need(gait, legs, paired, "one left and one right leg")
        phases = [0.0 if leg.side > 0 else 0.5 for leg in legs]
        return np.asarray(phases), duty or DUTY[gait]
    _need(gait, legs, gait != "run", "two legs (four or more legs walk, trot, pace, canter or gallop)")
    if gait in QUAD_PHASES:
        _need(gait, legs, rows == 2 and paired, "four legs in a front and a hind pair")
        table = QUAD_PHASES[gait]
        return np.asarray([table[(leg.row, leg.side)] for leg in legs]), duty or DUTY[gait]
    if gait == "tripod":
        _need(gait, legs, rows >= 3 and paired, "six or more legs in left/right pairs")
        return np.asarray([0.5 * ((leg.row + (leg.side < 0)) % 2) for leg in legs]), duty or DUTY[gait]
    _need(gait, legs, rows >= 2 and paired, "four or more legs in left/right pairs")  # walk, wave
    phases = [((rows - 1 - leg.row) + (rows if leg.side < 0 else 0)) / n for leg in legs]
    return np.asarray(phases), duty or 1.0 - 1.0 / n
