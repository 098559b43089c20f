"""Synthetic smooth deformations (bend and twist along the principal axis) to measure curves on static meshes.

Used by tests and benchmarks when simulated poses of a mesh are not at hand: the motion is smooth in space and
time, like a real elastic deformation, so differences in the floor come from the curves.
"""

from __future__ import annotations

import numpy as np

from .fields import group_pca


def bend_twist(vertices: np.ndarray, n_frames: int = 30, bend: float = 1.5, twist: float = 1.2,
               wobble: float = 0.05) -> np.ndarray:
    """(F, V, 3) float32 frames of the mesh vertices (V, 3) bending and twisting along its longest axis.

    bend : total bend angle (radians) at the last frame; twist : total twist angle from end to end;
    wobble : relative amplitude of a travelling radial wave. Frame 0 is the input itself.
    """
    v = np.asarray(vertices, dtype=np.float64)
    mean, axes = group_pca(v, np.zeros(len(v), np.int64), 1)
    a, b, c = axes[0, :, 0], axes[0, :, 1], axes[0, :, 2]
    d = v - mean[0]
    z, y, x = d @ a, d @ b, d @ c
    length = float(np.ptp(z)) or 1.0
    s = z / length
    out = np.empty((n_frames, len(v), 3))
    for f, t in enumerate(np.linspace(0.0, 1.0, n_frames)):
        ease = 0.5 - 0.5 * np.cos(np.pi * t)
        th = twist * ease * s
        yt = y * np.cos(th) - x * np.sin(th)
        xt = y * np.sin(th) + x * np.cos(th)
        scale = 1.0 + wobble * ease * np.sin(2 * np.pi * (s - t))
        yt, xt = yt * scale, xt * scale
        k = bend * ease / length
        if abs(k) < 1e-12:
            zb, yb = z, yt
        else:
            r0 = 1.0 / k
            zb = (r0 - yt) * np.sin(z / r0)
            yb = r0 - (r0 - yt) * np.cos(z / r0)
        out[f] = mean[0] + np.outer(zb, a) + np.outer(yb, b) + np.outer(xt, c)
    return out.astype(np.float32)
