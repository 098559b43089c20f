"""Skinning weights: per point, at most K non-negative weights summing to 1 that best blend the bones'
motions of its rest position, solved for all points at once as small quadratic programs (the Gram matrices of
the candidate bones' trajectories come from sums over frames, never from per-frame positions)."""

from __future__ import annotations

import numpy as np

from .rigid import CHUNK_POINTS, bone_sums, data_products

CANDIDATES = 8
"""Bones considered per point: its current influences and the best single bones."""
RIDGE = 1e-9
"""Relative ridge on the Gram matrices (bones that move a point alike stay solvable)."""


def pair_sums(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Over frames, for every pair of bones: sum R_a^T R_b (B, B, 3, 3), sum R_a^T t_b (B, B, 3), sum t_a.t_b
    (B, B)."""
    return (np.einsum("faji,fbjk->abik", R, R), np.einsum("faji,fbj->abi", R, t),
            np.einsum("fai,fbi->ab", t, t))


def simplex_qp(G: np.ndarray, c: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Weights (n, m) minimising w^T G w - 2 c^T w with sum w = 1 and w >= 0 over the ``active`` (n, m)
    entries (the others 0): the equality-constrained solution, dropping the most negative weight until
    none is left."""
    n, m = c.shape
    active = active.copy()
    scale = np.maximum(np.trace(G, axis1=1, axis2=2) / m, 1e-300)
    G = G + RIDGE * scale[:, None, None] * np.eye(m)
    w = np.zeros((n, m))
    todo = np.ones(n, bool)
    for _ in range(m):
        idx = np.flatnonzero(todo)
        if not len(idx):
            break
        a = active[idx]
        K = np.zeros((len(idx), m + 1, m + 1))
        both = a[:, :, None] & a[:, None, :]
        K[:, :m, :m] = np.where(both, G[idx], 0.0) + np.where(~a, 1.0, 0.0)[:, :, None] * np.eye(m)
        K[:, :m, m] = a
        K[:, m, :m] = a
        rhs = np.concatenate([np.where(a, c[idx], 0.0), np.ones((len(idx), 1))], axis=1)
        sol = np.linalg.solve(K, rhs[..., None])[..., 0][:, :m]
        sol = np.where(a, sol, 0.0)
        worst = np.argmin(sol, axis=1)
        negative = sol[np.arange(len(idx)), worst] < 0
        w[idx[~negative]] = sol[~negative]
        active[idx[negative], worst[negative]] = False
        todo[idx[~negative]] = False
    return w


def solve_weights(Xt: np.ndarray, rest: np.ndarray, R: np.ndarray, t: np.ndarray, index: np.ndarray,
                  weight: np.ndarray, influences: int, sparse_ms: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """New influences (P, K) int64 and weights (P, K) of trajectories Xt (P, F, 3) for bone transforms
    (F, B, 3, 3) / (F, B, 3), starting
    from the current ``index``/``weight`` (P, K0) (kept among the candidates, so no point gets worse).
    ``sparse_ms`` > 0: each point keeps the fewest influences (weights solved again on them) whose mean
    square distance over frames is at most this above its best with K (zero weights for the others)."""
    P, B = rest.shape[0], t.shape[1]
    m = min(CANDIDATES, B)
    k = min(influences, m)
    Q, S, U = pair_sums(R, t)
    rt, tt = bone_sums(R, t)
    F = t.shape[0]
    out_i = np.zeros((P, k), np.int64)
    out_w = np.zeros((P, k))
    for s in range(0, P, CHUNK_POINTS):
        block = slice(s, min(s + CHUNK_POINTS, P))
        p = rest[block]
        Z, y = data_products(Xt, R, t, block)
        c_all = np.einsum("vi,vbi->vb", p, Z) + y  # (n, B) sum_f (R_b p + t_b) . x
        g_diag = F * np.einsum("vi,vi->v", p, p)[:, None] + 2 * p @ rt.T + tt[None]
        score = g_diag - 2 * c_all  # single-bone error less |x|^2
        current = np.zeros_like(score, bool)
        np.put_along_axis(current, index[block], weight[block] > 0, axis=1)
        score = np.where(current, -np.inf, score)
        cand = np.argsort(score, axis=1, kind="stable")[:, :m]
        G = _gram(p, cand, Q, S, U)
        c = np.take_along_axis(c_all, cand, 1)
        w = simplex_qp(G, c, np.ones(cand.shape, bool))
        if k < m:  # keep the K largest and solve again on them
            top = np.argsort(-w, axis=1, kind="stable")[:, :k]
            keep = np.zeros_like(w, bool)
            np.put_along_axis(keep, top, True, axis=1)
            w = simplex_qp(G, c, keep & (w > 0))
            cand = np.take_along_axis(cand, top, 1)
            w = np.take_along_axis(w, top, 1)
            G = np.take_along_axis(np.take_along_axis(G, top[:, :, None], 1), top[:, None, :], 2)
            c = np.take_along_axis(c, top, 1)
        if sparse_ms > 0 and k > 1:
            w = _sparser(G, c, w, sparse_ms * F)
        out_i[block], out_w[block] = cand, w
    order = np.argsort(-out_w, axis=1, kind="stable")
    return np.take_along_axis(out_i, order, 1), np.take_along_axis(out_w, order, 1)


def _sparser(G: np.ndarray, c: np.ndarray, w: np.ndarray, allowed: float) -> np.ndarray:
    """Weights (n, k) on the fewest of each point's influences (its largest weights, solved again on them)
    whose objective w^T G w - 2 c^T w (a sum over frames of squared distances, less a constant) is at most
    ``allowed`` above that of ``w``."""
    full = _objective(G, c, w)
    rank = np.argsort(np.argsort(-w, axis=1, kind="stable"), axis=1, kind="stable")
    out, done = w.copy(), np.zeros(len(w), bool)
    for kept in range(1, w.shape[1]):
        idx = np.flatnonzero(~done)
        if not len(idx):
            break
        v = simplex_qp(G[idx], c[idx], (rank[idx] < kept) & (w[idx] > 0))
        ok = _objective(G[idx], c[idx], v) <= full[idx] + allowed
        out[idx[ok]] = v[ok]
        done[idx[ok]] = True
    return out


def _objective(G: np.ndarray, c: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(n,) w^T G w - 2 c^T w of each point."""
    return np.einsum("vi,vij,vj->v", w, G, w) - 2.0 * np.einsum("vi,vi->v", c, w)


def _gram(p: np.ndarray, cand: np.ndarray, Q: np.ndarray, S: np.ndarray, U: np.ndarray) -> np.ndarray:
    """(n, m, m) Gram matrices, over frames, of the candidate bones' (n, m) motions of points p (n, 3)."""
    n, m = cand.shape
    a, b = cand[:, :, None], cand[:, None, :]
    pp = (p[:, :, None] * p[:, None, :]).reshape(n, 9, 1)
    G = (Q.reshape(*Q.shape[:2], 9)[a, b].reshape(n, m * m, 9) @ pp).reshape(n, m, m)
    G += ((S[a, b] + S[b, a]).reshape(n, m * m, 3) @ p[:, :, None]).reshape(n, m, m) + U[a, b]
    return G
