"""Foot paths: Eq. 9-10 of the cyclic-animation paper per foot, each with its own phase.

With the Eq. 9 angle theta_i(t) of foot i, the foot moves from its rest position by
    y_i = (H + H_side) max(sin theta_i, 0) + H_side_F,    z_i = -(L + L_side) cos theta_i
(y up, z forward). Foot i touches down at phase phi_i and stays down for the duty factor beta of the cycle:
with u = frac(f t - phi_i), the swing (u >= beta) runs theta linearly over [2 pi, 3 pi] (Eq. 9 as printed,
the foot lifts and swings forward), and the stance (u < beta) warps theta over [pi, 2 pi] as
theta = 2 pi - arccos(2 u / beta - 1), so that z falls linearly from +L to -L: the stance foot moves back
under the body at the constant speed v = 2 L f / beta, and a root moved forward at v keeps it still on the
ground. The swing's forward path holds the foot still on the ground (moving back under the body at v)
until it is LIFT of the leg up and lands the same way, so a lifting or landing sole never scuffs the
ground; between those points it follows Eq. 9's -cos. ``literal`` uses theta = 2 pi (f t - phi_i) + pi and
y = H sin(2 pi f t), Eq. 10 as printed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gaits import GaitParams

LIFT = 0.02
"""A swinging foot leaves (and reaches) its ground spot straight up (down) over this share of the leg."""


@dataclass(frozen=True)
class FootPaths:
    """Per frame and foot: offset (K, n, 3) from the foot's rest position in world axes, stance (K, n) bool,
    bump (K, n) in [0, 1] (sin^2 over each stance: 0 at touch-down and lift-off, 1 at mid-stance), and
    forward (K, n) the signed z of Eq. 10 (how far ahead of its rest place each foot is)."""

    offset: np.ndarray
    stance: np.ndarray
    bump: np.ndarray
    forward: np.ndarray


def cycle_phase(params: GaitParams, times: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """u (K, n) in [0, 1): where in its own cycle each foot is (0 = touch-down)."""
    t = np.asarray(times, np.float64).reshape(-1, 1)
    return np.mod(params.frequency * t - np.asarray(phases)[None, :], 1.0)


def eq9_angle(u: np.ndarray, duty: float) -> np.ndarray:
    """The Eq. 9 angle theta (K, n) of each foot: warped over the stance so z is linear, linear in swing."""
    stance = u < duty
    s = np.where(stance, u / duty, 0.0)
    w = np.where(stance, 0.0, (u - duty) / (1.0 - duty))
    return np.where(stance, 2 * np.pi - np.arccos(np.clip(2 * s - 1, -1.0, 1.0)), 2 * np.pi + np.pi * w)


def swing_forward(u: np.ndarray, duty: float, height: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Forward offsets (K, n) of swinging feet (as fractions of the leg; u >= duty): still in the ground's
    frame while within LIFT of the ground after lift-off and before touch-down, Eq. 9's -cos from just
    behind -L to just ahead of +L between (height, length (n,): H + H_side and L + L_side)."""
    w = np.clip((u - duty) / (1.0 - duty), 0.0, 1.0)
    back = 2.0 * length * (1.0 - duty) / duty  # how far the body moves over the swing
    ratio = np.clip(LIFT / np.maximum(height, 1e-300), 0.0, 1.0)
    w0 = np.minimum(np.arcsin(ratio) / np.pi, 0.2)
    start, end = -length - back * w0, length + back * w0
    m = np.clip((w - w0) / (1.0 - 2.0 * w0), 0.0, 1.0)
    middle = start + (end - start) * 0.5 * (1.0 - np.cos(np.pi * m))
    return np.where(w < w0, -length - back * w, np.where(w > 1.0 - w0, length + back * (1.0 - w), middle))


def side_terms(params: GaitParams, sides: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-foot H + H_side, H_side_F and L + L_side (n,) as fractions of the leg length (right: side < 0)."""
    right = np.asarray(sides) < 0
    h = params.step_height + np.where(right, params.height_right, params.height_left)
    lift = np.where(right, params.lift_right, params.lift_left)
    length = params.step_length + np.where(right, params.length_right, params.length_left)
    return h, lift, length


def foot_paths(params: GaitParams, times: np.ndarray, phases: np.ndarray, duty: float, sides: np.ndarray,
               up: np.ndarray, forward: np.ndarray, leg: float) -> FootPaths:
    """Eq. 10 offsets of every foot at times (K,) seconds; phases (n,), sides (n,), leg the length unit."""
    u = cycle_phase(params, times, phases)
    h, lift, length = side_terms(params, sides)
    if params.literal:
        theta = 2 * np.pi * (u + 0.5)
        t = np.asarray(times, np.float64).reshape(-1, 1)
        y = h * np.sin(2 * np.pi * params.frequency * t) + lift
        stance = np.sin(theta) < 0
    else:
        theta = eq9_angle(u, duty)
        y = h * np.maximum(np.sin(theta), 0.0) + lift
        stance = u < duty
    z = -length * np.cos(theta)
    if not params.literal:
        z = np.where(u < duty, z, swing_forward(u, duty, h + 0.0 * u, length + 0.0 * u))
    offset = (y[..., None] * up + z[..., None] * forward) * leg
    bump = np.where(u < duty, np.sin(np.pi * np.minimum(u / duty, 1.0)) ** 2, 0.0)
    return FootPaths(offset, stance, bump, z * leg)


def travel_speed(params: GaitParams, duty: float, leg: float) -> float:
    """Root speed (units per second) that keeps stance feet still: the stride 2 L over the stance time
    beta / f (literal Eq. 10: the mean speed of the half cycle a foot sweeps back)."""
    share = 0.5 if params.literal else duty
    return 2.0 * params.step_length * leg * params.frequency / share
