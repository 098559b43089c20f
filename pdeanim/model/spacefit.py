"""The space half of the variable projection: choose space kind and D per curve+coordinate.

For fixed (kind, D) the 4 space functions of an item (one curve, one coordinate) span a subspace of its
N points; the part of every frame orthogonal to it is the *spatial floor*, which no time model can remove.
With the Gram matrix G = sum_frames y y^T of an item, floor(D) = trace(G) - trace(U^T G U) for an
orthonormal basis U of the space functions (SVD, so short curves with N < 4 are fine). D is searched on a
coarse grid for both space kinds, then refined (one parabolic step, then a few golden-section steps),
vectorised over all items.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .families import SPACE_KINDS, space_basis

D_GRID = np.concatenate([[0.0], np.geomspace(0.5, 48.0, 10)])
"""Coarse grid of D values searched for every item and space kind (10 ratios of 1.66: the parabolic step
and the golden section recover what a finer grid would find; 15 values cost ~25 % more time for < 0.01 %
rms)."""
RANK_TOL = 1e-6
GAIN_TOL = 1e-9
"""Relative energy gain needed to move away from D = 0 or from the grid value (ties keep the simpler D)."""
COND_MAX = 1e4
"""Largest condition number of a curve's space basis kept; beyond it float32 coefficients lose accuracy."""


@dataclass
class SpaceProjection:
    """Orthonormal space bases of all items at their chosen (kind, D).

    U : (K, N, 4) float64 orthonormal columns (zero columns where the basis is rank-deficient);
    to_coef : (K, 4, 4) float64, balanced space coefficients a = to_coef @ z for z = U^T y;
    kind : (K,) int (index into SPACE_KINDS); D : (K,) float64 (already rounded to float32 values).
    """

    U: np.ndarray
    to_coef: np.ndarray
    kind: np.ndarray
    D: np.ndarray


def orthonormal_basis(u: np.ndarray, mask: np.ndarray, D: np.ndarray, kind: str,
                      with_cond: bool = False) -> tuple[np.ndarray, ...]:
    """(U (K, N, 4), to_coef (K, 4, 4)) for items with parameters u (K, N), mask (K, N), D (K,).

    Directions the curve's points cannot determine (N < 4, coincident points) get zero columns. With
    ``with_cond`` also the condition numbers (K,) of the bases on the curves' points (same SVD).
    """
    S = space_basis(u, D, kind) * mask[..., None]
    K, N = S.shape[:2]
    if N < 4:  # pad with zero rows so the SVD always has 4 columns of U
        S = np.concatenate([S, np.zeros((K, 4 - N, 4))], axis=1)
    U, s, Vt = np.linalg.svd(S, full_matrices=False)
    keep = s > RANK_TOL * np.maximum(s[:, :1], 1e-300)
    U = (U * keep[:, None, :])[:, :N]
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    to_coef = np.swapaxes(Vt, -1, -2) * inv[:, None, :]
    if with_cond:
        return U, to_coef, _condition(s, mask)
    return U, to_coef


def _condition(s: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(K,) condition numbers of bases with singular values s (K, >=1) on curves with point masks (K, N)."""
    k = np.minimum(np.minimum(mask.sum(axis=1), 4), s.shape[1]) - 1
    return s[:, 0] / np.maximum(s[np.arange(len(s)), k], 1e-300)


CHOL_COND_MAX = 1e6
"""Matrices whose condition number may exceed this (bound: trace(M) ||L^-1||_F^2) take the eigh path."""


def _pinv_sym(M: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of symmetric positive semi-definite (C, n, n) matrices (small n).

    Provably well-conditioned matrices (cond <= CHOL_COND_MAX, where the eigh cut-off cannot apply): the
    inverse by Cholesky and triangular inverse, unrolled over the n^2 entries as (C,) vectors (far faster
    than a LAPACK call per 4 x 4 matrix); all others: :func:`_pinv_eigh`, unchanged.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # bad rows go to eigh below
        inv, ok = _inv_cholesky(M)
    if not np.all(ok):
        inv[~ok] = _pinv_eigh(M[~ok])
    return inv


def _inv_cholesky(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M^-1 (C, n, n), ok (C,)): unrolled Cholesky inverse; ok where cond(M) <= CHOL_COND_MAX provably."""
    C, n, _ = M.shape
    ok = np.ones(C, dtype=bool)
    L = [[np.zeros(C)] * n for _ in range(n)]  # L[i][j], lower triangular
    for j in range(n):
        d = M[:, j, j] - sum((L[j][k] * L[j][k] for k in range(j)), np.zeros(C))
        ok &= d > 0
        L[j][j] = np.sqrt(np.where(ok, d, 1.0))
        for i in range(j + 1, n):
            L[i][j] = (M[:, i, j] - sum((L[i][k] * L[j][k] for k in range(j)), np.zeros(C))) / L[j][j]
    Li = [[np.zeros(C)] * n for _ in range(n)]  # L^-1 by forward substitution
    for j in range(n):
        Li[j][j] = 1.0 / L[j][j]
        for i in range(j + 1, n):
            Li[i][j] = -sum((L[i][k] * Li[k][j] for k in range(j, i)), np.zeros(C)) / L[i][i]
    # lambda_max <= trace(M) and lambda_min = sigma_min(L)^2 >= 1 / ||L^-1||_F^2
    frob = sum((Li[i][j] * Li[i][j] for i in range(n) for j in range(i + 1)), np.zeros(C))
    ok &= np.trace(M, axis1=1, axis2=2) * frob <= CHOL_COND_MAX
    inv = np.empty_like(M)
    for i in range(n):  # M^-1 = L^-T L^-1: entry (i, j) = sum_k Li[k][i] Li[k][j], k >= max(i, j)
        for j in range(i, n):
            inv[:, i, j] = inv[:, j, i] = sum((Li[k][i] * Li[k][j] for k in range(j, n)), np.zeros(C))
    return inv, ok


def _pinv_eigh(M: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of symmetric positive semi-definite (..., 4, 4) matrices (eigh, relative cut-off)."""
    w, V = np.linalg.eigh(M)
    keep = w > (RANK_TOL**2) * np.maximum(w[..., -1:], 1e-300)
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    return (V * inv[..., None, :]) @ np.swapaxes(V, -1, -2)


def captured_energy(u: np.ndarray, mask: np.ndarray, gram: np.ndarray, D: np.ndarray, kind: str,
                    per_curve: int = 1) -> np.ndarray:
    """(K,) energy of the items' data that the space basis at D represents: trace((S^T S)^+ S^T G S).

    u, mask : (K / per_curve, N) shared by ``per_curve`` consecutive items (3 when x, y, z share u);
    gram : (K, N, N); D : (K / per_curve,). Used for the D search; the final projection uses an SVD.
    """
    S = space_basis(u, D, kind) * mask[..., None]  # (C, N, 4)
    inv = _pinv_sym(np.swapaxes(S, 1, 2) @ S)  # (C, 4, 4)
    K, N = gram.shape[:2]
    C = len(S)
    # the items of a curve share S: one (per_curve N, N) @ (N, 4) product per curve (same sums as per item)
    GS = (gram.reshape(C, per_curve * N, N) @ S).reshape(C, per_curve, N, 4)
    A = np.swapaxes(S, 1, 2)[:, None] @ GS  # (C, per_curve, 4, 4)
    return np.einsum("cab,cwab->cw", inv, A).reshape(K)


def _shared_u(u: np.ndarray) -> bool:
    """Whether consecutive item triples share their u (chord mode)."""
    return len(u) % 3 == 0 and np.array_equal(u[0::3], u[1::3]) and np.array_equal(u[0::3], u[2::3])


def search_D(u: np.ndarray, mask: np.ndarray, gram: np.ndarray, kinds: tuple[str, ...] = SPACE_KINDS,
             refine_iters: int = 3, check_cond: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best (kind index (K,), D (K,), floor energy (K,)) per item: coarse grid over D, one parabolic step,
    then (refine_iters > 0) golden-section refinement. check_cond=False leaves the fall-back to D = 0 of
    ill-conditioned bases to :func:`project_items` (``fallback=True``), which reuses its SVD for it."""
    energy = np.trace(gram, axis1=1, axis2=2)
    K = len(u)
    share = 3 if _shared_u(u) else 1
    uc, mc = u[::share], mask[::share]
    cap = np.empty((len(kinds), len(D_GRID), K))
    for i, kind in enumerate(kinds):
        for g, d in enumerate(D_GRID):
            cap[i, g] = captured_energy(uc, mc, gram, np.full(len(uc), d), kind, share)
    flat = cap.reshape(-1, K)
    # D = 0 (the cubics, best conditioned) wins unless another D captures clearly more
    best = np.argmax(flat + GAIN_TOL * energy * (np.arange(len(flat)) % len(D_GRID) == 0)[:, None], axis=0)
    kind_i, grid_i = np.divmod(best, len(D_GRID))
    lo = D_GRID[np.maximum(grid_i - 1, 0)]
    hi = D_GRID[np.minimum(grid_i + 1, len(D_GRID) - 1)]
    ar = np.arange(K)
    f = [cap[kind_i, np.clip(grid_i + k, 0, len(D_GRID) - 1), ar] for k in (-1, 0, 1)]
    groups = _groups(u, mask, gram, kind_i, kinds)
    gain_tol = GAIN_TOL * energy
    D, capD = _parabolic(groups, lo, D_GRID[grid_i], hi, f, gain_tol)
    if refine_iters > 0:
        D, capD = _golden(groups, lo, hi, D, capD, gain_tol, refine_iters)
    D = D.astype(np.float32).astype(np.float64)
    if check_cond:
        D, kind_i, capD = _well_conditioned(u, mask, gram, kind_i, D, capD, cap[0, 0], kinds)
    return kind_i, D, np.maximum(energy - capD, 0.0)


def _well_conditioned(u, mask, gram, kind_i, D, capD, cap0, kinds):
    """Fall back to D = 0 where the chosen basis is ill-conditioned on the curve's points (float32 safety)."""
    cond = np.ones(len(u))
    for i, kind in enumerate(kinds):
        sel = kind_i == i
        if np.any(sel):
            s = np.linalg.svd(space_basis(u[sel], D[sel], kind) * mask[sel][..., None], compute_uv=False)
            cond[sel] = _condition(s, mask[sel])
    bad = cond > COND_MAX
    return np.where(bad, 0.0, D), np.where(bad, 0, kind_i), np.where(bad, cap0, capD)


def _groups(u, mask, gram, kind_i, kinds):
    """Per space kind (selection, u, mask, gram of its items, kind): split once for all refinement calls."""
    out = []
    for i, kind in enumerate(kinds):
        sel = np.flatnonzero(kind_i == i)
        if len(sel):
            out.append((sel, u[sel], mask[sel], gram[sel], kind))
    return out


def _captured_mixed(groups, D) -> np.ndarray:
    """(K,) captured energy of every item at its own D (K,), each with its space kind (see _groups)."""
    out = np.empty(len(D))
    for sel, u, mask, gram, kind in groups:
        out[sel] = captured_energy(u, mask, gram, D[sel], kind)
    return out


def _parabolic(groups, x0, x1, x2, f, gain_tol):
    """One parabolic step through the best grid value and its neighbours; kept where it captures more."""
    f0, f1, f2 = f
    a, b = (x1 - x0) * (f1 - f2), (x1 - x2) * (f1 - f0)
    den = a - b
    ok = (np.abs(den) > 1e-300) & (x0 < x1) & (x1 < x2)
    vertex = x1 - 0.5 * ((x1 - x0) * a - (x1 - x2) * b) / np.where(ok, den, 1.0)
    vertex = np.where(ok, np.clip(vertex, x0, x2), x1)
    fv = _captured_mixed(groups, vertex)
    better = fv > f1 + gain_tol
    return np.where(better, vertex, x1), np.where(better, fv, f1)


def _golden(groups, lo, hi, best_D, best_cap, gain_tol, iters):
    """Vectorised golden-section maximisation of captured energy over D in [lo, hi] per item."""
    r = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo.copy(), hi.copy()
    c, d = b - r * (b - a), a + r * (b - a)
    fc, fd = _captured_mixed(groups, c), _captured_mixed(groups, d)
    for _ in range(iters):
        left = fc > fd
        a, b = np.where(left, a, c), np.where(left, d, b)
        c, d = np.where(left, b - r * (b - a), d), np.where(left, c, a + r * (b - a))
        f_new = _captured_mixed(groups, np.where(left, c, d))
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
    x = np.where(fc > fd, c, d)
    fx = np.maximum(fc, fd)
    better = fx > best_cap + gain_tol
    return np.where(better, x, best_D), np.where(better, fx, best_cap)


def project_items(u: np.ndarray, mask: np.ndarray, kind_i: np.ndarray, D: np.ndarray,
                  kinds: tuple[str, ...] = SPACE_KINDS, fallback: bool = False) -> SpaceProjection:
    """Orthonormal bases and coefficient maps at the chosen (kind, D) of every item.

    fallback=True: items whose basis is ill-conditioned (cond > COND_MAX, from the same SVD) fall back to
    D = 0 (kind 0), as :func:`search_D` does with ``check_cond=True``.
    """
    K, N = u.shape
    U = np.zeros((K, N, 4))
    to_coef = np.zeros((K, 4, 4))
    cond = np.ones(K)
    for i, kind in enumerate(kinds):
        sel = kind_i == i
        if np.any(sel):
            U[sel], to_coef[sel], cond[sel] = orthonormal_basis(
                u[sel], mask[sel], D[sel], kind, with_cond=True
            )
    kind_i = kind_i.astype(np.int64)
    bad = cond > COND_MAX
    if fallback and np.any(bad):
        kind_i, D = np.where(bad, 0, kind_i), np.where(bad, 0.0, D)
        U[bad], to_coef[bad] = orthonormal_basis(u[bad], mask[bad], D[bad], kinds[0])
    return SpaceProjection(U, to_coef, kind_i, D)
