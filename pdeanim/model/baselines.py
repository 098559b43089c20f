"""Static per-frame baselines of the paper (Sec. 4): least-squares cubic Bezier (Eq. 17-18) and uniform cubic
B-spline (Eq. 19-22) curves, fitted frame by frame on the same curve parameters u as the PDE model.

Both are linear least squares in the control points with a design that depends only on u, so all frames of
a curve are solved at once (pseudo-inverse by SVD, batched over curves). With 4 control points and the
clamped uniform knot vector the cubic B-spline equals the cubic Bezier curve (as in the paper's Table 2);
more control points give a genuine uniform B-spline.
"""

from __future__ import annotations

from math import comb

import numpy as np

from ..errors import ParameterError


def bernstein_basis(u: np.ndarray, degree: int = 3) -> np.ndarray:
    """Bernstein polynomials (..., N, degree + 1) at u (..., N) (Eq. 17)."""
    u = np.asarray(u, dtype=np.float64)[..., None]
    i = np.arange(degree + 1)
    coeff = np.array([comb(degree, int(k)) for k in i], dtype=np.float64)
    return coeff * u**i * (1.0 - u) ** (degree - i)


def clamped_uniform_knots(n_ctrl: int, degree: int = 3) -> np.ndarray:
    """Clamped knot vector with uniform interior knots: (n_ctrl + degree + 1,) over [0, 1]."""
    if n_ctrl < degree + 1:
        raise ParameterError(f"a degree-{degree} B-spline needs at least {degree + 1} control points")
    inner = np.linspace(0.0, 1.0, n_ctrl - degree + 1)
    return np.concatenate([np.zeros(degree), inner, np.ones(degree)])


def bspline_basis(u: np.ndarray, n_ctrl: int = 4, degree: int = 3) -> np.ndarray:
    """B-spline basis N_{i,degree}(u) by the Cox-de Boor recursion (Eq. 20-21): (..., N, n_ctrl)."""
    T = clamped_uniform_knots(n_ctrl, degree)
    u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)[..., None]
    n_int = len(T) - 1
    left, right = T[:-1], T[1:]
    last = np.flatnonzero(right > left)[-1]  # u = 1 belongs to the last non-empty span
    N = ((u >= left) & (u < right)).astype(np.float64)
    N[..., last] = np.where(u[..., 0] == 1.0, 1.0, N[..., last])
    for q in range(1, degree + 1):
        cols = n_int - q
        a_den = T[q:q + cols] - T[:cols]
        b_den = T[q + 1:q + 1 + cols] - T[1:1 + cols]
        a = np.where(a_den > 0, (u - T[:cols]) / np.where(a_den > 0, a_den, 1.0), 0.0)
        b = np.where(b_den > 0, (T[q + 1:q + 1 + cols] - u) / np.where(b_den > 0, b_den, 1.0), 0.0)
        N = a * N[..., :cols] + b * N[..., 1:cols + 1]
    return N


def fit_static(points: np.ndarray, u: np.ndarray, basis: np.ndarray, mask: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares control points per frame and curve.

    points : (F, C, N, 3); u : (C, N); basis : (C, N, P) evaluated at u; mask : (C, N) bool (padding).
    Returns (control (F, C, P, 3), fitted points (F, C, N, 3)).
    """
    B = basis if mask is None else basis * mask[..., None]
    Y = np.asarray(points, np.float64) * (1.0 if mask is None else mask[None, :, :, None])
    pinv = np.linalg.pinv(B)  # (C, P, N)
    ctrl = np.einsum("cpn,fcnw->fcpw", pinv, Y)
    return ctrl, np.einsum("cnp,fcpw->fcnw", basis, ctrl)


def fit_bezier(points: np.ndarray, u: np.ndarray, mask: np.ndarray | None = None, degree: int = 3):
    """Cubic (by default) Bezier fit per frame: (control (F, C, degree+1, 3), fitted (F, C, N, 3))."""
    return fit_static(points, u, bernstein_basis(u, degree), mask)


def fit_bspline(points: np.ndarray, u: np.ndarray, mask: np.ndarray | None = None, n_ctrl: int = 4,
                degree: int = 3):
    """Clamped uniform B-spline fit per frame: (control (F, C, n_ctrl, 3), fitted (F, C, N, 3))."""
    return fit_static(points, u, bspline_basis(u, n_ctrl, degree), mask)
