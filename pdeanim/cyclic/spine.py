"""The spine of a chain of PDE patches: the polynomial A0(u) of each patch joined into one curve.

The chain is parametrised by s in [0, 1] from head to tail; patch b covers s in [b / B, (b + 1) / B] with its
local u = B s - b. A0(u_j) is the mean of boundary curve j, so the spine passes through the centroid of every
shared curve and is continuous from patch to patch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .pde_surface import poly_basis


def split_s(s: np.ndarray, n_patches: int) -> tuple[np.ndarray, np.ndarray]:
    """Global chain parameter s (Q,) in [0, 1] to (patch (Q,) int64, local u (Q,) float64 in [0, 1])."""
    x = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0) * n_patches
    patch = np.minimum(np.floor(x).astype(np.int64), n_patches - 1)
    return patch, x - patch


@dataclass(frozen=True)
class Spine:
    """Spine polynomials coef (B, 2N, 3) float64: A0_b(u) = sum_k coef[b, k] u^k."""

    coef: np.ndarray

    @property
    def n_patches(self) -> int:
        """B, the number of patches along the chain."""
        return int(self.coef.shape[0])

    def at(self, s: np.ndarray, deriv: int = 0) -> np.ndarray:
        """Spine points (deriv = 0) or d^k/ds^k of them at chain parameters s (Q,): (Q, 3) float64."""
        patch, u = split_s(s, self.n_patches)
        basis = poly_basis(u, self.coef.shape[1], deriv) * float(self.n_patches) ** deriv
        return np.einsum("qk,qkc->qc", basis, self.coef[patch])

    def polyline(self, per_patch: int = 16) -> np.ndarray:
        """The spine sampled as a polyline of B * per_patch + 1 points: (n, 3) float64."""
        return self.at(np.linspace(0.0, 1.0, self.n_patches * per_patch + 1))

    def length(self, per_patch: int = 32) -> float:
        """Arc length of the spine (from a fine polyline)."""
        return float(np.linalg.norm(np.diff(self.polyline(per_patch), axis=0), axis=1).sum())
