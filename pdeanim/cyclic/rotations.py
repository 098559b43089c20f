"""Batched rigid motions of joint world matrices: rotations about axes and between directions, and turning a
joint's subtree about a point (every frame at once)."""

from __future__ import annotations

import numpy as np


def unit(x: np.ndarray) -> np.ndarray:
    """Vectors (..., 3) scaled to length 1 (zero vectors stay zero)."""
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-300)


def axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations (K, 3, 3) by angle (K,) radians about unit axis (3,) or (K, 3) (right-handed)."""
    ang = np.asarray(angle, np.float64).reshape(-1)
    ax = np.broadcast_to(np.asarray(axis, np.float64), (len(ang), 3))
    k = np.zeros((len(ang), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -ax[:, 2], ax[:, 1], -ax[:, 0]
    k = k - k.transpose(0, 2, 1)
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations (K, 3, 3) turning unit vectors a (K, 3) onto unit vectors b (K, 3)."""
    v = np.cross(a, b)
    c = np.einsum("ki,ki->k", a, b)
    vx = np.zeros((len(a), 3, 3))
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx = vx - vx.transpose(0, 2, 1)
    return np.eye(3) + vx + vx @ vx / np.maximum(1.0 + c, 1e-12)[:, None, None]


def turn_subtree(world: np.ndarray, sub: np.ndarray, rot: np.ndarray, centre: np.ndarray) -> None:
    """Rotate the joints in mask sub (J,) of world (K, J, 4, 4) in place by rot (K, 3, 3) about centre (K, 3)
    or (3,)."""
    g = np.zeros((len(rot), 4, 4))
    g[:, :3, :3] = rot
    c = np.broadcast_to(np.asarray(centre, np.float64), (len(rot), 3))
    g[:, :3, 3] = c - np.einsum("kij,kj->ki", rot, c)
    g[:, 3, 3] = 1.0
    world[:, sub] = g[:, None] @ world[:, sub]


def shift_subtree(world: np.ndarray, sub: np.ndarray, offset: np.ndarray) -> None:
    """Translate the joints in mask sub (J,) of world (K, J, 4, 4) in place by offset (K, 3)."""
    trans = world[..., :3, 3]  # (K, J, 3) view
    trans[:, sub] += np.asarray(offset, np.float64)[:, None]
