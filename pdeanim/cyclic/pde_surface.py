"""Analytic solution of the elliptic PDE (d2/du2 + a^2 d2/dv2)^N X = 0 with periodic v.

Each boundary curve is sampled at P points v_i = 2 pi i / P and split into Fourier modes (numpy FFT). Mode 0
gives the spine polynomial A0(u) of degree 2N-1; mode n gives A_n(u), B_n(u) as combinations of
u^p e^{+a n u} and u^p e^{-a n u} (p < N). Modes above the truncation M are not dropped: like the remainder
R(u, v) of the paper they use the single exponent w = a (M + 1), so the surface reproduces every boundary
sample exactly. The growing exponentials are written balanced, e^{s (u - 1)}, so nothing overflows.

A patch is described by 2N conditions (u_j, d_j): the curve j is the d_j-th u-derivative of X at u = u_j
(positions at u = 0, 1/3, 2/3, 1, or positions and first derivatives at u = 0 and 1 for N = 2). A chain of
patches stacks the coefficient arrays on a leading patch axis and evaluates them all in one call.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb, factorial

import numpy as np

from ..errors import ParameterError

MAX_EXPONENT = 30.0
"""Largest mode exponent a n allowed. Between interior boundary curves a mode grows like e^{a n / 3}, so
beyond this the patch is numerically meaningless (and the boundary solve loses its 1e-9 accuracy)."""

CHUNK = 8192
"""Points evaluated per batch (keeps the per-point coefficient gathers to a few tens of MB)."""

MIN_A = 0.2
"""Smallest smoothing parameter: as a n -> 0 the exponential basis tends to polynomials and the solve loses
accuracy. Boundary samples are reproduced to 1e-10 for N = 2 over the whole range (0.2 <= a n <= 30); N = 3
needs 0.7 <= a n <= 15 for 1e-9 (its interior curves are closer, so modes grow faster between them)."""


def fourier_modes(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Real Fourier coefficients of periodic curves sampled at v_i = 2 pi i / P.

    curves : (..., P, 3) float
    returns c0 (..., 3), cos (..., H, 3), sin (..., H, 3) with H = P // 2 (modes 1..H), such that
    curve(v) = c0 + sum_n cos_n cos(n v) + sin_n sin(n v) at every sample.
    """
    c = np.asarray(curves, dtype=np.float64)
    p = c.shape[-2]
    spec = np.fft.rfft(c, axis=-2) / p
    h = p // 2
    cos = 2.0 * spec[..., 1:h + 1, :].real
    sin = -2.0 * spec[..., 1:h + 1, :].imag
    if p % 2 == 0:  # the Nyquist mode is not doubled and has no sine part
        cos[..., -1, :] *= 0.5
        sin[..., -1, :] = 0.0
    return spec[..., 0, :].real, cos, sin


def poly_basis(u: np.ndarray, order: int, deriv: int = 0) -> np.ndarray:
    """The d-th derivative of the monomials u^k, k = 0..order-1: (..., order) float64 for u (...,)."""
    u = np.asarray(u, dtype=np.float64)[..., None]
    k = np.arange(order)
    coef = np.array([factorial(j) / factorial(j - deriv) if j >= deriv else 0.0 for j in k])
    return coef * np.power(u, np.maximum(k - deriv, 0))


def exp_basis(u: np.ndarray, sigma: np.ndarray, n_order: int, deriv: int = 0) -> np.ndarray:
    """The d-th u-derivative of the 2N functions of one Fourier mode, balanced against overflow.

    u : (Q,) float, sigma : (H,) float > 0 (a n per mode) -> (Q, H, 2N) float64 with columns
    [u^p e^{sigma (u - 1)} for p < N] then [u^p e^{-sigma u} for p < N].
    """
    u = np.asarray(u, dtype=np.float64)[:, None]
    s = np.asarray(sigma, dtype=np.float64)[None, :]
    cols = []
    for lam, grow in ((s, True), (-s, False)):
        e = np.exp(lam * (u - 1.0)) if grow else np.exp(lam * u)
        for p in range(n_order):
            acc = np.zeros(np.broadcast_shapes(u.shape, s.shape))
            for j in range(min(deriv, p) + 1):
                acc = acc + comb(deriv, j) * factorial(p) / factorial(p - j) * u ** (p - j) * lam ** (
                    deriv - j
                )
            cols.append(acc * e)
    return np.stack(cols, axis=-1)


@dataclass(frozen=True)
class PatchConditions:
    """Where the 2N boundary curves of a patch sit: parameter u_j and derivative order d_j of each."""

    u: tuple[float, ...]
    deriv: tuple[int, ...]

    @property
    def order(self) -> int:
        """N, half the number of conditions."""
        return len(self.u) // 2

    @staticmethod
    def positions(n_order: int = 2) -> PatchConditions:
        """2N position curves at equally spaced u = j / (2N - 1)."""
        k = 2 * n_order
        return PatchConditions(tuple(j / (k - 1) for j in range(k)), (0,) * k)

    @staticmethod
    def hermite(n_order: int = 2) -> PatchConditions:
        """Positions and derivatives up to N-1 at u = 0 and u = 1."""
        return PatchConditions((0.0,) * n_order + (1.0,) * n_order, tuple(range(n_order)) * 2)

    def validate(self) -> None:
        """Raise ParameterError unless there are 2N >= 2 conditions with orders below 2N."""
        if len(self.u) != len(self.deriv) or len(self.u) < 2 or len(self.u) % 2:
            raise ParameterError("a PDE patch needs an even number (2N >= 2) of boundary conditions")
        if min(self.deriv) < 0 or max(self.deriv) >= len(self.u):
            raise ParameterError("boundary derivative orders must lie in 0..2N-1")
        if len(set(zip(self.u, self.deriv, strict=True))) != len(self.u):
            raise ParameterError("boundary conditions must be distinct")


@dataclass(frozen=True)
class PdePatches:
    """Coefficients of one or more PDE patches sharing N, a, M and the number of samples per curve.

    coef0 : (B, 2N, 3) spine polynomial coefficients (A0(u) = sum_k coef0[k] u^k)
    coefc, coefs : (B, H, 2N, 3) coefficients of the cosine and sine parts of modes 1..H
    sigma : (H,) exponent per mode, a * min(n, M + 1)
    """

    n_order: int
    a: float
    modes: int
    coef0: np.ndarray
    coefc: np.ndarray
    coefs: np.ndarray
    sigma: np.ndarray

    @property
    def n_patches(self) -> int:
        """B, the number of patches."""
        return int(self.coef0.shape[0])

    def evaluate(
        self, patch: np.ndarray, u: np.ndarray, v: np.ndarray, du: int = 0, dv: int = 0
    ) -> np.ndarray:
        """Surface points (or their du-th u and dv-th v derivative) at scattered parameters.

        patch : (Q,) int, u : (Q,) float in [0, 1], v : (Q,) float radians -> (Q, 3) float64
        """
        patch = np.asarray(patch, dtype=np.int64)
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        if len(u) > CHUNK:  # bound the (Q, H, 2N, 3) gathers
            return np.concatenate([self.evaluate(patch[i:i + CHUNK], u[i:i + CHUNK], v[i:i + CHUNK], du, dv)
                                   for i in range(0, len(u), CHUNK)])
        poly = poly_basis(u, 2 * self.n_order, du) * (dv == 0)  # (Q, 2N); the spine has no v
        phi = exp_basis(u, self.sigma, self.n_order, du)  # (Q, H, 2N)
        n = np.arange(1, len(self.sigma) + 1, dtype=np.float64)
        ang = n[None, :] * v[:, None] + dv * np.pi / 2
        scale = n[None, :] ** dv
        weights = np.concatenate([poly, (phi * (scale * np.cos(ang))[..., None]).reshape(len(u), -1),
                                  (phi * (scale * np.sin(ang))[..., None]).reshape(len(u), -1)], axis=1)
        coef = self.stacked()
        out = np.empty((len(u), 3))
        for b in np.unique(patch):  # one small matrix product per patch
            sel = patch == b
            out[sel] = weights[sel] @ coef[b]
        return out

    def stacked(self) -> np.ndarray:
        """All coefficients of each patch as one (B, 2N + 2 H 2N, 3) matrix, in the order evaluate uses."""
        b = self.n_patches
        return np.concatenate(
            [self.coef0, self.coefc.reshape(b, -1, 3), self.coefs.reshape(b, -1, 3)], axis=1
        )

    def spine(self, patch: np.ndarray, u: np.ndarray, du: int = 0) -> np.ndarray:
        """The spine A0(u) (or its du-th derivative) of the given patches: (Q, 3) float64."""
        patch = np.asarray(patch, dtype=np.int64)
        return np.einsum("qk,qkc->qc", poly_basis(u, 2 * self.n_order, du), self.coef0[patch])

    def grid(self, n_u: int, n_v: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sample every patch on an n_u x n_v grid (v periodic, endpoint excluded).

        returns points (B, n_u, n_v, 3), u (n_u,), v (n_v,)
        """
        u = np.linspace(0.0, 1.0, n_u)
        v = np.arange(n_v) * (2 * np.pi / n_v)
        b = np.repeat(np.arange(self.n_patches), n_u * n_v)
        uu = np.tile(np.repeat(u, n_v), self.n_patches)
        vv = np.tile(v, self.n_patches * n_u)
        return self.evaluate(b, uu, vv).reshape(self.n_patches, n_u, n_v, 3), u, v


def condition_matrices(cond: PatchConditions, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Matrices mapping coefficients to boundary values: mode 0 (2N, 2N) and modes (H, 2N, 2N)."""
    n = cond.order
    g0 = np.stack([poly_basis(np.array(uj), 2 * n, dj) for uj, dj in zip(cond.u, cond.deriv, strict=True)])
    rows = [exp_basis(np.array([uj]), sigma, n, dj)[0] for uj, dj in zip(cond.u, cond.deriv, strict=True)]
    return g0, np.stack(rows, axis=1)  # (H, 2N rows, 2N cols)


def _balanced_solve(g: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve g x = rhs for square g (..., K, K) broadcast against rhs (B, ..., K, 3), with rows and columns
    scaled to unit max first: the basis functions differ in size by orders of magnitude (u^p e^{-s u} peaks
    at (p / s)^p e^{-p}); equilibration cuts the condition number of the solve (~1e7 to ~1e3 for N = 3)."""
    col = np.abs(g).max(axis=-2, keepdims=True)  # (..., 1, K)
    gc = g / col
    row = np.abs(gc).max(axis=-1, keepdims=True)  # (..., K, 1)
    x = np.linalg.solve((gc / row)[None], rhs / row[None])
    return x / np.swapaxes(col, -1, -2)[None]


def solve_patches(curves: np.ndarray, cond: PatchConditions | None = None, *, modes: int = 6,
                  a: float = 1.0) -> PdePatches:
    """Solve the PDE for a batch of patches, each from its 2N boundary curves.

    curves : (B, 2N, P, 3) float (curve j of patch b sampled at v_i = 2 pi i / P); modes = M, the number of
    Fourier modes solved with their own exponent a n (the rest use w = a (M + 1)); a > 0 the smoothing
    parameter, a (modes + 1) <= MAX_EXPONENT. Returns the coefficients; the surface reproduces every boundary
    sample to rounding.
    """
    cond = cond or PatchConditions.positions(2)
    cond.validate()
    c = np.asarray(curves, dtype=np.float64)
    if c.ndim != 4 or c.shape[1] != len(cond.u) or c.shape[3] != 3:
        raise ParameterError(f"boundary curves must be (B, {len(cond.u)}, P, 3), got {c.shape}")
    if c.shape[2] < 3 or not np.isfinite(c).all():
        raise ParameterError("boundary curves need at least 3 finite points each")
    if not a >= MIN_A or modes < 0:
        raise ParameterError(f"the smoothing parameter a must be >= {MIN_A} and modes >= 0")
    h = c.shape[2] // 2
    sigma = a * np.minimum(np.arange(1, h + 1), modes + 1).astype(np.float64)
    if h and sigma.max() > MAX_EXPONENT:
        raise ParameterError(f"a * (modes + 1) = {sigma.max():g} is over {MAX_EXPONENT:g}: lower the modes "
                             f"or a")
    g0, gn = condition_matrices(cond, sigma)
    c0, cc, cs = fourier_modes(c)  # (B, 2N, 3), (B, 2N, H, 3)
    coef0 = _balanced_solve(g0, c0)
    coefc = _balanced_solve(gn, np.moveaxis(cc, 2, 1))  # rhs (B, H, 2N, 3)
    coefs = _balanced_solve(gn, np.moveaxis(cs, 2, 1))
    return PdePatches(cond.order, float(a), int(modes), coef0, coefc, coefs, sigma)


def biharmonic_residual(patches: PdePatches, patch: int, u: np.ndarray, v: np.ndarray,
                        h: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """Finite-difference (d2/du2 + a^2 d2/dv2)^2 X at (u, v) and the size of its separate terms.

    A 5x5-point stencil of step h around each of the Q points (u (Q,), v (Q,)); returns the residual
    (Q, 3) and the scale |X_uuuu| + 2 a^2 |X_uuvv| + a^4 |X_vvvv| (Q, 3) for a relative check.
    """
    offs = np.arange(-2, 3) * h
    du, dv = np.meshgrid(offs, offs, indexing="ij")
    uu = (u[:, None] + du.ravel()[None]).ravel()
    vv = (v[:, None] + dv.ravel()[None]).ravel()
    x = patches.evaluate(np.full(len(uu), patch), uu, vv).reshape(len(u), 5, 5, 3)
    d2 = np.array([1.0, -2.0, 1.0]) / h**2
    d4 = np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / h**4
    x_uuuu = np.einsum("i,qic->qc", d4, x[:, :, 2])
    x_vvvv = np.einsum("j,qjc->qc", d4, x[:, 2, :])
    x_uuvv = np.einsum("i,j,qijc->qc", d2, d2, x[:, 1:4, 1:4])
    a2 = patches.a**2
    res = x_uuuu + 2 * a2 * x_uuvv + a2 * a2 * x_vvvv
    return res, np.abs(x_uuuu) + 2 * a2 * np.abs(x_uuvv) + a2 * a2 * np.abs(x_vvvv)
