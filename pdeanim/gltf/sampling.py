"""Animation sampling per the glTF 2.0 spec, vectorised over sample times: STEP, LINEAR (slerp for
rotations) and CUBICSPLINE (Hermite with in/out tangents), clamped outside the key range; and TRS matrices."""

from __future__ import annotations

import numpy as np

from ..errors import InputError, PosesInputError

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Shortest-path spherical interpolation of unit quaternions (K, 4) xyzw at fractions s (K,)."""
    q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
    q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.abs(dot).clip(max=1.0)
    theta = np.arccos(dot)
    sin = np.sin(theta)
    near = sin < 1e-6
    safe = np.where(near, 1.0, sin)
    w0 = np.where(near, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    w1 = np.where(near, s, np.sin(s * theta) / safe)
    out = w0[:, None] * q0 + w1[:, None] * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _segments(keys: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index of the key before each time, the fraction into its segment and the segment length."""
    i = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, max(len(keys) - 2, 0))
    if len(keys) < 2:
        return i, np.zeros_like(t), np.ones_like(t)
    dt = keys[i + 1] - keys[i]
    s = np.clip((t - keys[i]) / dt, 0.0, 1.0)
    return i, s, dt


def sample(keys: np.ndarray, values: np.ndarray, interpolation: str, t: np.ndarray, *,
           rotation: bool = False, error: type[InputError] = PosesInputError) -> np.ndarray:
    """Sample one animation sampler at times t (K,): keys (n,), values (n, w) or (3n, w) for CUBICSPLINE
    (in-tangent, value, out-tangent per key); returns (K, w) float64."""
    keys = np.asarray(keys, np.float64).reshape(-1)
    values = np.asarray(values, np.float64)
    n = len(keys)
    if interpolation not in INTERPOLATIONS:
        raise error(f"unknown animation interpolation {interpolation!r}")
    if n == 0 or not np.all(np.isfinite(keys)) or np.any(np.diff(keys) <= 0):
        raise error("animation key times must be finite and strictly increasing")
    cubic = interpolation == "CUBICSPLINE"
    if len(values) != (3 * n if cubic else n):
        raise error(f"animation sampler has {len(values)} output values for {n} keys ({interpolation})")
    t = np.asarray(t, np.float64)
    if cubic:
        return _cubic(keys, values.reshape(n, 3, -1), t, rotation)
    if interpolation == "STEP" or n == 1:
        i = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, n - 1)
        return values[i]
    i, s, _ = _segments(keys, t)
    if rotation:
        return slerp(values[i], values[i + 1], s)
    return values[i] * (1.0 - s)[:, None] + values[i + 1] * s[:, None]


def _cubic(keys: np.ndarray, v: np.ndarray, t: np.ndarray, rotation: bool) -> np.ndarray:
    """CUBICSPLINE: v (n, 3, w) = (in-tangent, value, out-tangent); tangents are scaled by the key gap."""
    if len(keys) == 1:
        out = np.repeat(v[:1, 1], len(t), axis=0)
    else:
        i, s, dt = _segments(keys, t)
        s2, s3 = s * s, s * s * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        out = (h00[:, None] * v[i, 1] + (h10 * dt)[:, None] * v[i, 2] + h01[:, None] * v[i + 1, 1]
               + (h11 * dt)[:, None] * v[i + 1, 0])
        before, after = t <= keys[0], t >= keys[-1]
        out[before], out[after] = v[0, 1], v[-1, 1]
    if rotation:
        out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return out


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) xyzw (normalised first)."""
    q = np.asarray(q, np.float64)
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def trs_matrices(translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Local matrices T * R * S (..., 4, 4) from translation (..., 3), rotation xyzw (..., 4), scale (...,
    3)."""
    shape = np.broadcast_shapes(np.shape(translation)[:-1], np.shape(rotation)[:-1], np.shape(scale)[:-1])
    m = np.zeros((*shape, 4, 4))
    rot = quaternion_matrices(np.broadcast_to(np.asarray(rotation, np.float64), (*shape, 4)))
    m[..., :3, :3] = rot * np.broadcast_to(np.asarray(scale, np.float64), (*shape, 3))[..., None, :]
    m[..., :3, 3] = np.broadcast_to(np.asarray(translation, np.float64), (*shape, 3))
    m[..., 3, 3] = 1.0
    return m
