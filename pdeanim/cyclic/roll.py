"""Foot roll of plantigrade legs (heel and toes on the ground at rest: humans, bears): the heel strikes with
the toes up and the sole rolls down about the heel's back edge, stays flat through mid-stance, and at
push-off the heel lifts about the ball (the toe joint) while the toes stay flat on the ground; through the
swing the foot turns from its push-off pitch back to its heel-strike pitch."""

from __future__ import annotations

import numpy as np

from .footpaths import cycle_phase
from .gaits import GaitParams
from .rotations import axis_angle
from .skeleton import Skeleton

HEEL = 0.15
"""Share of the stance the heel strike lasts (the sole is flat after it)."""
TOE = 0.7
"""Share of the stance after which the heel lifts."""


def roll_pitch(u: np.ndarray, duty: float, heel: float, toe: float) -> tuple[np.ndarray, np.ndarray]:
    """Pitch (K,) in radians (toes up > 0) and pivot blend (K,) (1: heel pivot, 0: ball pivot) of a foot at
    cycle positions u (K,) (0 = touch-down) with heel-strike and push-off angles heel and toe."""
    s = np.clip(u / duty, 0.0, 1.0)
    w = np.clip((u - duty) / (1.0 - duty), 0.0, 1.0)
    smooth = w * w * (3.0 - 2.0 * w)
    strike = heel * np.clip(1.0 - s / HEEL, 0.0, 1.0) ** 2
    push = -toe * np.clip((s - TOE) / (1.0 - TOE), 0.0, 1.0) ** 2
    stance = u < duty
    pitch = np.where(stance, np.where(s < HEEL, strike, push), -toe * (1.0 - smooth) + heel * smooth)
    blend = np.where(stance, (s < TOE).astype(float), smooth)
    return pitch, blend


def heel_point(sk: Skeleton, foot: int, forward: np.ndarray) -> np.ndarray:
    """The back edge of a foot's own ground contact at rest (its rearmost contact vertex; the point under
    the foot joint when it has none)."""
    pts = sk.contact_at[foot] if sk.contact_at is not None else np.zeros((0, 3))
    if not len(pts):
        return np.array([sk.positions[foot, 0], sk.ground, sk.positions[foot, 2]])
    return pts[int(np.argmin(pts @ forward))]


def rolled_targets(sk: Skeleton, foot: int, toe: int, targets: np.ndarray, pitch: np.ndarray,
                   blend: np.ndarray, left: np.ndarray, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the foot joint goes when the foot, level at targets (K, 3), turns by pitch about its pivot (the
    heel's back edge or the ball, blended): the rolled targets (K, 3) and the turns (K, 3, 3)."""
    ankle = sk.positions[foot]
    pivot = blend[:, None] * (heel_point(sk, foot, forward) - ankle) + (1 - blend[:, None]) * (
        sk.positions[toe] - ankle)
    turn = axis_angle(left, -pitch)
    return targets + pivot - np.einsum("kij,kj->ki", turn, pivot), turn


def roll_of(params: GaitParams, times: np.ndarray, phase: float, duty: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pitch and pivot blend (K,) of a plantigrade foot stepping at ``phase`` (the gait's heel_strike and
    toe_off angles; no roll with literal paths)."""
    u = cycle_phase(params, times, np.array([phase]))[:, 0]
    if params.literal:
        return np.zeros_like(u), np.ones_like(u)
    return roll_pitch(u, duty, params.heel_strike, params.toe_off)
