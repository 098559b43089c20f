"""Shared helpers of the model benchmarks: synthetic deforming surfaces of a chosen size."""

from __future__ import annotations

import numpy as np

from pdeanim.poses import Poses, make_poses


def torus_poses(n_u: int = 150, n_v: int = 100, n_frames: int = 40, seed: int = 0) -> Poses:
    """A torus of n_u * n_v vertices deformed by smooth travelling waves over n_frames frames."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n_u, endpoint=False)[:, None]
    b = np.linspace(0, 2 * np.pi, n_v, endpoint=False)[None, :]
    t = np.linspace(0, 1, n_frames)[:, None, None]
    phase = rng.uniform(0, 2 * np.pi, 3)
    r = 0.5 + 0.08 * np.sin(3 * a + 2 * np.pi * t + phase[0]) * np.cos(2 * b + phase[1])
    R = 2.0 + 0.2 * np.sin(a - 2 * np.pi * t + phase[2])
    x = (R + r * np.cos(b)) * np.cos(a)
    y = (R + r * np.cos(b)) * np.sin(a)
    z = r * np.sin(b) + 0.3 * t * np.sin(a)
    verts = np.stack([x, y, np.broadcast_to(z, x.shape)], axis=-1).reshape(n_frames, -1, 3)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    v00 = i * n_v + j
    v10 = ((i + 1) % n_u) * n_v + j
    v01 = i * n_v + (j + 1) % n_v
    v11 = ((i + 1) % n_u) * n_v + (j + 1) % n_v
    faces = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3),
                            np.stack([v00, v11, v01], -1).reshape(-1, 3)])
    return make_poses(verts.astype(np.float32), faces)


def ring_curves(n_u: int, n_v: int):
    """Curves along the v direction of torus_poses, cut into runs of 25 points."""
    from pdeanim.curveset import CurveSet

    rows = np.arange(n_u * n_v).reshape(n_u, n_v)
    runs = [r for row in rows for r in np.array_split(row, max(1, n_v // 25))]
    return CurveSet.from_lists(runs)
