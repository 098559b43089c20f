"""A body as a chain of biharmonic PDE patches between consecutive cross-section curves.

With K = 3 B + 1 curves, patch b interpolates curves 3b, 3b+1, 3b+2, 3b+3 at u = 0, 1/3, 2/3, 1, so
neighbouring patches share their end curve. The chain is addressed by s in [0, 1] (see :mod:`.spine`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .pde_surface import PatchConditions, PdePatches, solve_patches
from .spine import Spine, split_s

CURVES_PER_PATCH = 3
"""Curves a patch adds to the chain (4 per patch, the last shared with the next patch)."""


def valid_curve_count(n_curves: int) -> int:
    """The smallest usable number of curves >= n_curves (3 B + 1 with B >= 1)."""
    b = max(1, -(-(int(n_curves) - 1) // CURVES_PER_PATCH))
    return CURVES_PER_PATCH * b + 1


@dataclass(frozen=True)
class BodySurface:
    """The PDE surface of a body: curves (K, P, 3) float64 and the solved patches."""

    curves: np.ndarray
    patches: PdePatches

    @staticmethod
    def from_curves(curves: np.ndarray, *, modes: int = 6, a: float = 1.0) -> BodySurface:
        """Solve one biharmonic patch per 4 consecutive curves; curves (K, P, 3) with K = 3 B + 1."""
        c = np.asarray(curves, dtype=np.float64)
        if c.ndim != 3 or c.shape[2] != 3 or c.shape[0] < 4 or (c.shape[0] - 1) % CURVES_PER_PATCH:
            raise ParameterError(f"a patch chain needs (3 B + 1, P, 3) curves, got {c.shape}")
        b = (c.shape[0] - 1) // CURVES_PER_PATCH
        idx = CURVES_PER_PATCH * np.arange(b)[:, None] + np.arange(4)[None, :]
        return BodySurface(c, solve_patches(c[idx], PatchConditions.positions(2), modes=modes, a=a))

    @property
    def n_patches(self) -> int:
        """B, the number of patches."""
        return self.patches.n_patches

    @property
    def spine(self) -> Spine:
        """The chain's spine A0 as a :class:`Spine`."""
        return Spine(self.patches.coef0)

    def curve_s(self) -> np.ndarray:
        """Chain parameter s (K,) of each boundary curve."""
        return np.arange(len(self.curves)) / (len(self.curves) - 1)

    def evaluate(self, s: np.ndarray, v: np.ndarray, ds: int = 0, dv: int = 0) -> np.ndarray:
        """Surface points (or derivatives d/ds, d/dv) at chain parameters s (Q,), v (Q,): (Q, 3) float64."""
        patch, u = split_s(s, self.n_patches)
        return self.patches.evaluate(patch, u, v, ds, dv) * float(self.n_patches) ** ds

    def grid(self, n_s: int, n_v: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The surface on an n_s x n_v grid over the whole chain: points (n_s, n_v, 3), s (n_s,), v (n_v,)."""
        s = np.linspace(0.0, 1.0, n_s)
        v = np.arange(n_v) * (2 * np.pi / n_v)
        pts = self.evaluate(np.repeat(s, n_v), np.tile(v, n_s))
        return pts.reshape(n_s, n_v, 3), s, v

    def grid_mesh(self, n_s: int, n_v: int) -> tuple[np.ndarray, np.ndarray]:
        """The grid as a triangle mesh (open at both ends): vertices (n_s n_v, 3), faces (T, 3) int32."""
        pts, _, _ = self.grid(n_s, n_v)
        idx = np.arange(n_s * n_v).reshape(n_s, n_v)
        nxt = np.roll(idx, -1, axis=1)
        fa = np.stack([idx[:-1], idx[1:], nxt[1:]], axis=-1).reshape(-1, 3)
        fb = np.stack([idx[:-1], nxt[1:], nxt[:-1]], axis=-1).reshape(-1, 3)
        return pts.reshape(-1, 3), np.concatenate([fa, fb]).astype(np.int32)
