"""Pure, vectorised XPBD constraint functions for tetrahedra (co-rotated linear elasticity in XPBD form).

Each function takes the corner positions of K independent tets and returns position corrections; nothing is
stored except the per-tet rotation guesses, passed in and returned. The energy per unit rest volume is
mu |F - R|^2 + lambda/2 (det F - 1)^2 (R: rotation of F's polar decomposition), which linearises exactly to
linear elasticity with Lame parameters (mu, lambda). It is split into a deviatoric constraint C_D = |F - R|_F
with compliance 1/(2 mu V) and a volume constraint C_H = det F - 1 with compliance 1/(lambda V). Both vanish
at rest, so even a nearly rigid material projects back to its rest shape without fighting itself.
"""

from __future__ import annotations

import numpy as np

ROTATION_ITERATIONS = 1
"""Warm-started iterations of the rotation extraction of Muller et al. 2016 per constraint solve (the guess
carries over from the previous substep, so the rotation is tracked, not recomputed from scratch)."""


def deformation_gradient(x: np.ndarray, dm_inv: np.ndarray) -> np.ndarray:
    """(K, 3, 3) F = Ds Dm^-1 from corners x (K, 4, 3) and rest inverses dm_inv (K, 3, 3)."""
    ds = (x[:, 1:] - x[:, :1]).transpose(0, 2, 1)
    return ds @ dm_inv


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(K, 3, 3) rotation matrices of unit quaternions q (K, 4) stored (w, x, y, z)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def extract_rotation(f: np.ndarray, q: np.ndarray, iterations: int = ROTATION_ITERATIONS) -> np.ndarray:
    """(K, 4) unit quaternions of the rotations closest to F (K, 3, 3), refined from the guesses q (K, 4)."""
    q = q.copy()
    for _ in range(iterations):
        r = quat_to_matrix(q)
        num = np.cross(r, f, axis=1).sum(axis=2)  # sum over columns of r_i x a_i
        den = np.abs(np.einsum("kij,kij->k", r, f)) + 1e-9
        omega = num / den[:, None]
        # (1, omega/2): no trig, same fixpoint
        dq = np.concatenate([np.ones((len(q), 1)), 0.5 * omega], axis=1)
        q = quat_multiply(dq, q)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, 4) Hamilton products a * b of quaternions (w, x, y, z)."""
    aw, av = a[:, :1], a[:, 1:]
    bw, bv = b[:, :1], b[:, 1:]
    return np.concatenate([aw * bw - np.sum(av * bv, axis=1, keepdims=True),
                           aw * bv + bw * av + np.cross(av, bv)], axis=1)


def corner_gradients(dc_df: np.ndarray, dm_inv: np.ndarray) -> np.ndarray:
    """(K, 4, 3) gradients of a constraint w.r.t. the corners, from dC/dF (K, 3, 3)."""
    g123 = (dc_df @ dm_inv.transpose(0, 2, 1)).transpose(0, 2, 1)
    return np.concatenate([-g123.sum(axis=1, keepdims=True), g123], axis=1)


def xpbd_correction(c: np.ndarray, grads: np.ndarray, w: np.ndarray, alpha_tilde: np.ndarray,
                    lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One XPBD update: ((K, 4, 3) corrections w_i grad_i C dlambda, (K,) dlambda).

    c : (K,) constraint values; grads : (K, 4, 3); w : (K, 4) inverse masses; alpha_tilde : (K,) alpha / dt^2;
    lam : (K,) multipliers accumulated so far in this step (zeros for the first iteration).
    """
    denom = np.einsum("kij,kij,ki->k", grads, grads, w) + alpha_tilde
    dlam = np.divide(-c - alpha_tilde * lam, denom, out=np.zeros_like(c), where=denom > 0)
    return grads * (w * dlam[:, None])[:, :, None], dlam


def deviatoric_correction(x: np.ndarray, w: np.ndarray, dm_inv: np.ndarray, alpha_tilde: np.ndarray,
                          lam: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corrections (K, 4, 3), dlambda (K,) and refined rotations (K, 4) of C_D = |F - R|_F."""
    f = deformation_gradient(x, dm_inv)
    q = extract_rotation(f, q)
    diff = f - quat_to_matrix(q)
    c = np.sqrt(np.einsum("kij,kij->k", diff, diff))
    df = diff / np.maximum(c, 1e-12)[:, None, None]
    dx, dlam = xpbd_correction(c, corner_gradients(df, dm_inv), w, alpha_tilde, lam)
    return dx, dlam, q


def hydrostatic_correction(x: np.ndarray, w: np.ndarray, dm_inv: np.ndarray, alpha_tilde: np.ndarray,
                           lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corrections (K, 4, 3) and dlambda (K,) of C_H = det F - 1 for corners x (K, 4, 3)."""
    f = deformation_gradient(x, dm_inv)
    f0, f1, f2 = f[:, :, 0], f[:, :, 1], f[:, :, 2]
    cof = np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=2)
    c = np.einsum("ki,ki->k", f0, cof[:, :, 0]) - 1.0
    return xpbd_correction(c, corner_gradients(cof, dm_inv), w, alpha_tilde, lam)
