"""Leg IK on world matrices, every frame at once: place a leg's foot joint on a target.

Positions are solved in the leg's plane (spanned by the top-to-foot line and the current bend of the leg),
then each bone is turned onto its new direction, top down, carrying its subtree. One bone: an aim. Two
bones: the analytic triangle solution (the knee bends the way it bends now). Three bones (a digitigrade
hind leg): the knee and hock bends keep their rest ratio, beta2 = r beta1, so the top-to-foot distance is a
monotone function of beta1 alone, solved by bisection; the chain is then turned so the foot lies on the
target line. A target out of reach is clamped to the reachable distance.
"""

from __future__ import annotations

import numpy as np

from .rotations import rotation_between, turn_subtree, unit

BISECTION_STEPS = 60


def _plane(pos: np.ndarray, target: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal in-plane axes (K, 3) x (toward the target) and y (toward the current bend of the leg)."""
    top, foot = pos[:, 0], pos[:, -1]
    line = unit(foot - top)
    bend = pos[:, 1] - top
    bend = bend - line * np.einsum("ki,ki->k", bend, line)[:, None]
    scale = np.linalg.norm(pos[:, 1] - top, axis=1)
    weak = np.linalg.norm(bend, axis=1) < 1e-3 * np.maximum(scale, 1e-300)
    bend = np.where(weak[:, None], fallback, bend)
    x = unit(target - top)
    y = bend - x * np.einsum("ki,ki->k", bend, x)[:, None]
    return x, unit(y)


def _planar_angles(pos: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Angles (K, B) of the bones of pos (K, B + 1, 3) in the plane (x, y)."""
    d = np.diff(pos, axis=1)
    return np.arctan2(np.einsum("kbi,ki->kb", d, y), np.einsum("kbi,ki->kb", d, x))


def _chain_points(lengths: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Planar joint points (K, B + 1, 2) of bones with lengths (B,) at absolute angles (K, B)."""
    steps = lengths[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], axis=2)
    return np.concatenate([np.zeros((len(angles), 1, 2)), np.cumsum(steps, axis=1)], axis=1)


def _three_bone(lengths: np.ndarray, rest_bends: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Planar points (K, 4, 2) of a three-bone chain whose bends keep the rest ratio and whose end lies on
    the +x axis at dist (K,) (clamped to the reachable range)."""
    b1, b2 = rest_bends
    ratio = b2 / b1 if abs(b1) > 1e-9 else -1.0
    sign = np.sign(b1) if abs(b1) > 1e-9 else 1.0
    grid = np.linspace(0.0, np.pi, 721)
    reach = np.linalg.norm(_chain_points(lengths, _bent(grid * sign, ratio))[:, -1], axis=1)
    stop = int(np.argmax(np.diff(reach) >= 0)) if np.any(np.diff(reach) >= 0) else len(grid) - 1
    lo_d, hi_d = reach[stop], reach[0]
    d = np.clip(dist, lo_d, hi_d * (1 - 1e-12))
    lo, hi = np.zeros_like(d), np.full_like(d, grid[stop])
    for _ in range(BISECTION_STEPS):  # reach falls as the bend grows on [0, grid[stop]]
        mid = 0.5 * (lo + hi)
        far = np.linalg.norm(_chain_points(lengths, _bent(mid * sign, ratio))[:, -1], axis=1) > d
        lo, hi = np.where(far, mid, lo), np.where(far, hi, mid)
    pts = _chain_points(lengths, _bent(0.5 * (lo + hi) * sign, ratio))
    turn = -np.arctan2(pts[:, -1, 1], pts[:, -1, 0])
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    return np.stack([c * pts[..., 0] - s * pts[..., 1], s * pts[..., 0] + c * pts[..., 1]], axis=2)


def _bent(beta1: np.ndarray, ratio: float) -> np.ndarray:
    """Absolute bone angles (K, 3) of a chain starting along +x with bends beta1 and ratio * beta1."""
    return np.stack([np.zeros_like(beta1), beta1, beta1 * (1.0 + ratio)], axis=1)


def _two_bone(lengths: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Planar points (K, 3, 2) of a two-bone chain ending at (dist, 0) with the knee on the +y side."""
    a, b = lengths
    d = np.clip(dist, abs(a - b) + 1e-9 * (a + b), (a + b) * (1 - 1e-9))
    cos_a = np.clip((a * a + d * d - b * b) / (2 * a * d), -1.0, 1.0)
    knee = np.stack([a * cos_a, a * np.sqrt(1 - cos_a**2)], axis=1)
    return np.stack([np.zeros_like(knee), knee, np.stack([d, np.zeros_like(d)], axis=1)], axis=1)


def solve_leg(world: np.ndarray, subtree: np.ndarray, joints: tuple[int, ...], target: np.ndarray,
              rest_bends: np.ndarray | None, fallback: np.ndarray) -> None:
    """Move the leg whose IK joints are ``joints`` (top .. foot, 2 to 4 joints) in world (K, J, 4, 4) in place
    so the foot reaches target (K, 3); rest_bends (2,) are a three-bone leg's signed rest bends; fallback
    (3,) is the bend direction for a straight leg."""
    pos = world[:, list(joints)][..., :3, 3].copy()
    top = pos[:, 0]
    lengths = np.linalg.norm(np.diff(pos[0], axis=0), axis=1)
    if len(joints) == 2:
        new = top[:, None] + lengths[0] * unit(target - top)[:, None] * np.array([0.0, 1.0])[None, :, None]
    else:
        x, y = _plane(pos, target, fallback)
        dist = np.linalg.norm(target - top, axis=1)
        if len(joints) == 3:
            flat = _two_bone(lengths, dist)
        else:
            flat = _three_bone(lengths, rest_bends, dist)
        new = top[:, None] + flat[..., :1] * x[:, None] + flat[..., 1:] * y[:, None]
    for i in range(len(joints) - 1):
        here = world[:, joints[i], :3, 3].copy()
        rot = rotation_between(unit(world[:, joints[i + 1], :3, 3] - here), unit(new[:, i + 1] - here))
        turn_subtree(world, subtree[joints[i]], rot, here)


def rest_bends(pos: np.ndarray) -> np.ndarray:
    """Signed bends (2,) of a three-bone chain at rest (pos (4, 3)) in its own plane."""
    x = unit(pos[-1] - pos[0])
    bend = pos[1] - pos[0]
    y = unit(bend - x * (bend @ x))
    ang = _planar_angles(pos[None], x[None], y[None])[0]
    return np.diff(ang)
