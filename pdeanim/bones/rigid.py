"""Rigid transforms of point sets: weighted Kabsch fits, vectorised over frames, and the error of every
(point, bone) pair computed from a few sums over frames instead of per-frame positions."""

from __future__ import annotations

import numpy as np

CHUNK_POINTS = 8192
"""Points per block where a (points x bones) array is built (memory bounded by the block)."""


def weighted_kabsch(rest: np.ndarray, weight: np.ndarray, target: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (F, 3, 3) and translations (F, 3) minimising sum_v || w_v (R p_v + t) - q_vf ||^2 for rest
    points p (n, 3), weights w (n,) and weighted targets q (n, F, 3) (the SSDR bone update; w = 1 is the
    plain rigid fit). Proper rotations only; identity where the weights are all 0."""
    F = target.shape[1]
    a = weight * weight
    total = a.sum()
    if total <= 0:
        return np.broadcast_to(np.eye(3), (F, 3, 3)).copy(), np.zeros((F, 3))
    pc = a @ rest / total
    qc = (weight @ target.reshape(len(weight), -1)).reshape(F, 3) / total  # sum a y / sum a, y = q / w
    H = ((weight[:, None] * (rest - pc)).T @ target.reshape(len(weight), -1)).reshape(3, F, 3)
    H = np.swapaxes(H, 0, 1)  # (F, 3, 3): sum_v w (p - pc)_i q_fj
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)))
    d[d == 0] = 1.0
    Vt[:, 2, :] *= d[:, None]
    R = np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)
    return R, qc - R @ pc


def moved(R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, F, 3) points (n, 3) moved by one bone's transforms (F, 3, 3), (F, 3)."""
    return np.swapaxes(R @ points.T, 1, 2).transpose(1, 0, 2) + t[None]


def bone_sums(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per bone, over frames: sum R^T t (B, 3) and sum |t|^2 (B,) (the point-independent parts of a bone's
    error)."""
    return np.einsum("fbji,fbj->bi", R, t), np.einsum("fbi,fbi->b", t, t)


def data_products(Xt: np.ndarray, R: np.ndarray, t: np.ndarray, points: slice) -> tuple[np.ndarray,
                                                                                        np.ndarray]:
    """For a block of trajectories Xt (P, F, 3): Z (n, B, 3) = sum_f R_fb^T x_vf and y (n, B) =
    sum_f t_fb . x_vf, one matrix product over the stacked frame coordinates."""
    F, B = t.shape[:2]
    Xv = Xt[points].reshape(-1, 3 * F)
    M = np.concatenate([R.transpose(0, 2, 1, 3).reshape(3 * F, 3 * B),
                        t.transpose(0, 2, 1).reshape(3 * F, B)], axis=1)
    # M[(f, j), (b, i)] = R[f, b, j, i]; M[(f, j), 3B + b] = t[f, b, j]
    P = Xv @ M
    return P[:, :3 * B].reshape(-1, B, 3), P[:, 3 * B:]


def single_bone_errors(Xt: np.ndarray, rest: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(P, B) sum over frames of the squared distance of each trajectory (Xt (P, F, 3)) to where bone b alone
    moves its rest position."""
    F = Xt.shape[1]
    rt, tt = bone_sums(R, t)
    out = np.empty((rest.shape[0], t.shape[1]))
    for s in range(0, rest.shape[0], CHUNK_POINTS):
        block = slice(s, min(s + CHUNK_POINTS, rest.shape[0]))
        Z, y = data_products(Xt, R, t, block)
        p = rest[block]
        xx = np.einsum("vfi,vfi->v", Xt[block], Xt[block])
        out[block] = (xx[:, None] + F * np.einsum("vi,vi->v", p, p)[:, None] + 2 * p @ rt.T + tt[None]
                      - 2 * (np.einsum("vi,vbi->vb", p, Z) + y))
    return np.maximum(out, 0.0)
