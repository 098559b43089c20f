"""The four closed-form families of m w_tt = D w_uuuu (paper 000, Eq. 5-8), in numerically balanced form.

A family is a time kind ("exp": {e^{mt}, e^{-mt}}, "trig": {cos mt, sin mt}) times a space kind
("D0": {e^{Du}, e^{-Du}, cos Du, sin Du}; "D1": {e^{a u} cos a u, e^{a u} sin a u, e^{-a u} cos a u,
e^{-a u} sin a u} with a = D / sqrt 2). Family codes follow the paper's equation order::

    0 = exp x D0 (Eq. 5)   1 = exp x D1 (Eq. 6)   2 = trig x D0 (Eq. 7)   3 = trig x D1 (Eq. 8)

Every family satisfies its PDE: w_tt = +-m^2 w and w_uuuu = +-D^4 w, so w_tt / w_uuuu is a constant.

**Balanced bases** (what the library fits, stores and evaluates; same span as the paper's, no overflow):

* time, in local segment time tau in [0, 1]: the end-interpolating pair
  phi0 = sinh(m (1 - tau)) / sinh m, phi1 = sinh(m tau) / sinh m (trig: sin; m -> 0 gives 1 - tau, tau).
  So the two time coefficients of a segment are the values of the track at its two ends.
* space, with s = u - 1/2: for D < D_SWITCH the "Taylor-stable" set, scaled by SMALL_SCALE = (1, 2, 4, 24)
  so that it tends to the cubic monomials {1, 2s, 4s^2, 8s^3} on [-1, 1] as D -> 0 (D0: (cosh x + cos x)/2,
  (sinh x + sin x)/(2D), (cosh x - cos x)/D^2, (sinh x - sin x)/D^3 with x = D s; D1: cosh x cos x,
  (cosh x sin x + sinh x cos x)/(2a), sinh x sin x / a^2, (cosh x sin x - sinh x cos x)/(2a^3) with x = a s,
  each times its scale); for D >= D_SWITCH the bounded set
  (D0: e^{-Du}, e^{D(u-1)}, cos Ds, sin Ds; D1: e^{-au} cos as, e^{-au} sin as, e^{a(u-1)} cos as,
  e^{a(u-1)} sin as), every function in [-1, 1].

**Exact map to the paper's basis**: :func:`space_to_paper` gives M (4, 4) with balanced_k(u) =
sum_b M[k, b] paper_b(u); :func:`time_to_paper` gives N (2, 2) with phi_i(tau(t)) = sum_a N[i, a] paper_a(t)
for global t and the global constant m / (t1 - t0). Balanced coefficients C (2, 4) become the paper's
c1..c8 as (N^T C M).ravel() (:func:`paper_coefficients`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError

TIME_KINDS = ("exp", "trig")
SPACE_KINDS = ("D0", "D1")
D_SWITCH = 4.0
"""Below this D the Taylor-stable space basis is used, at and above it the bounded exponential one."""
SQRT2 = math.sqrt(2.0)


def family_code(time_kind: str, space_kind: str) -> int:
    """The family code 0..3 (paper Eq. 5-8) of a time kind and a space kind."""
    if time_kind not in TIME_KINDS or space_kind not in SPACE_KINDS:
        raise ParameterError(f"unknown family ({time_kind!r}, {space_kind!r})")
    return 2 * TIME_KINDS.index(time_kind) + SPACE_KINDS.index(space_kind)


def family_kinds(code: int) -> tuple[str, str]:
    """(time_kind, space_kind) of a family code 0..3."""
    if code not in (0, 1, 2, 3):
        raise ParameterError(f"family code must be 0..3, got {code}")
    return TIME_KINDS[code // 2], SPACE_KINDS[code % 2]


# ---------------------------------------------------------------- stable scalar helpers

def _shc(y: np.ndarray, sinh_y: np.ndarray | None = None) -> np.ndarray:
    """sinh(y) / y, 1 at 0 (sinh_y: np.sinh(y) when already computed)."""
    return _over_y(y, np.sinh if sinh_y is None else sinh_y, 1.0)


def _sc(y: np.ndarray, sin_y: np.ndarray | None = None) -> np.ndarray:
    """sin(y) / y, 1 at 0 (sin_y: np.sin(y) when already computed)."""
    return _over_y(y, np.sin if sin_y is None else sin_y, -1.0)


def _over_y(y: np.ndarray, f, sign: float) -> np.ndarray:
    """f(y) / y for f = sinh (sign 1) or sin (sign -1); the series 1 +- y^2 / 6 where |y| < 1e-4.

    f is the function or its values at y; the series is evaluated on the small elements only.
    """
    y = np.asarray(y, dtype=np.float64)
    small = np.abs(y) < 1e-4
    ys = np.where(small, 1.0, y)
    out = (f(ys) if callable(f) else f) / ys
    if np.any(small):
        ysm = y[small]
        out[small] = 1.0 + ysm * ysm / 6.0 if sign > 0 else 1.0 - ysm * ysm / 6.0
    return out


def _series(fn_coeffs: list[float], x: np.ndarray) -> np.ndarray:
    return np.polynomial.polynomial.polyval(x, fn_coeffs)


def _taylor(kind: str, n: int = 24) -> np.ndarray:
    """Taylor coefficients of cosh, sinh, cos, sin up to degree n."""
    k = np.arange(n + 1)
    fact = np.array([math.factorial(i) for i in k], dtype=np.float64)
    even, odd = (k % 2 == 0), (k % 2 == 1)
    sign = np.where((k // 2) % 2 == 0, 1.0, -1.0)
    table = {"cosh": even / fact, "sinh": odd / fact, "cos": even * sign / fact, "sin": odd * sign / fact}
    return table[kind]


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.polynomial.polynomial.polymul(a, b)[: len(a)]


_SMS = (_taylor("sinh") - _taylor("sin"))[3:]  # (sinh x - sin x) / x^3
_CSC = (_mul(_taylor("cosh"), _taylor("sin")) - _mul(_taylor("sinh"), _taylor("cos")))[3:]  # /x^3


def _ratio3(x: np.ndarray, coeffs: np.ndarray, f_x: np.ndarray) -> np.ndarray:
    """f(x) / x^3 for an odd f with f = O(x^3), given f_x = f(x): series for |x| < 0.5 (evaluated on those
    elements only), the direct quotient elsewhere."""
    small = np.abs(x) < 0.5
    xs = np.where(small, 1.0, x)
    out = f_x / (xs * xs * xs)  # products, not pow: pow is ~100x slower per element
    if np.any(small):
        out[small] = _series(coeffs, x[small])
    return out


# ---------------------------------------------------------------- space bases

SMALL_SCALE = np.array([1.0, 2.0, 4.0, 24.0])
"""Scale of the Taylor-stable functions so that they tend to {1, x, x^2, x^3} with x = 2u - 1 in [-1, 1]."""


def _space_small(u: np.ndarray, D: np.ndarray, space_kind: str) -> np.ndarray:
    return _space_small_unscaled(u, D, space_kind) * SMALL_SCALE


def _space_small_unscaled(u: np.ndarray, D: np.ndarray, space_kind: str) -> np.ndarray:
    s = u - 0.5
    if space_kind == "D0":
        x = D * s
        sh, sn = np.sinh(x), np.sin(x)  # shared by the ratios below (same values as computing them apiece)
        g1 = 0.5 * (np.cosh(x) + np.cos(x))
        g2 = 0.5 * s * (_shc(x, sh) + _sc(x, sn))
        g3 = 0.5 * s * s * (_shc(0.5 * x) ** 2 + _sc(0.5 * x) ** 2)
        g4 = s * s * s * _ratio3(x, _SMS, sh - sn)
        return np.stack([g1, g2, g3, g4], axis=-1)
    x = D / SQRT2 * s
    ch, c, sh, sn = np.cosh(x), np.cos(x), np.sinh(x), np.sin(x)
    shc, sc = _shc(x, sh), _sc(x, sn)
    k1 = ch * c
    k2 = 0.5 * s * (ch * sc + shc * c)
    k3 = s * s * shc * sc
    k4 = 0.5 * (s * s * s) * _ratio3(x, _CSC, ch * sn - sh * c)
    return np.stack([k1, k2, k3, k4], axis=-1)


def _space_large(u: np.ndarray, D: np.ndarray, space_kind: str) -> np.ndarray:
    s = u - 0.5
    if space_kind == "D0":
        return np.stack([np.exp(-D * u), np.exp(D * (u - 1.0)), np.cos(D * s), np.sin(D * s)], axis=-1)
    a = D / SQRT2
    lo, hi, c, sn = np.exp(-a * u), np.exp(a * (u - 1.0)), np.cos(a * s), np.sin(a * s)
    return np.stack([lo * c, lo * sn, hi * c, hi * sn], axis=-1)


def space_basis(u: np.ndarray, D: np.ndarray | float, space_kind: str) -> np.ndarray:
    """Balanced space basis at parameters u.

    u : (..., N) float, curve parameter in [0, 1]; D : (...) float >= 0 (broadcast against u[..., 0]).
    Returns (..., N, 4) float64; spans the paper's space basis for D > 0 and the cubics at D = 0.
    """
    if space_kind not in SPACE_KINDS:
        raise ParameterError(f"space kind must be one of {SPACE_KINDS}, got {space_kind!r}")
    u = np.asarray(u, dtype=np.float64)
    D = np.abs(np.asarray(D, dtype=np.float64))
    lead = np.broadcast_shapes(u.shape[:-1], D.shape)
    u = np.broadcast_to(u, lead + u.shape[-1:])
    D = np.broadcast_to(D, lead)
    small = D < D_SWITCH
    if np.all(small):
        return _space_small(u, D[..., None], space_kind)
    if not np.any(small):
        return _space_large(u, D[..., None], space_kind)
    out = np.empty(u.shape + (4,))
    out[small] = _space_small(u[small], D[small][:, None], space_kind)
    out[~small] = _space_large(u[~small], D[~small][:, None], space_kind)
    return out


def space_basis_paper(u: np.ndarray, D: np.ndarray | float, space_kind: str) -> np.ndarray:
    """The paper's own space basis (Eq. 5-8), (..., N, 4) float64; overflows for large D (reference only)."""
    u = np.asarray(u, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64)[..., None]
    if space_kind == "D0":
        return np.stack([np.exp(D * u), np.exp(-D * u), np.cos(D * u), np.sin(D * u)], axis=-1)
    a = D / SQRT2
    ep, em, c, sn = np.exp(a * u), np.exp(-a * u), np.cos(a * u), np.sin(a * u)
    return np.stack([ep * c, ep * sn, em * c, em * sn], axis=-1)


def space_to_paper(D: float, space_kind: str) -> np.ndarray:
    """M (4, 4) with balanced_k(u) = sum_b M[k, b] paper_b(u), exact closed form; D must be > 0."""
    D = float(D)
    if not D > 0:
        raise ParameterError(
            "the paper's space basis is degenerate at D = 0 (the balanced one is the cubics)"
        )
    if space_kind == "D0":
        h = 0.5 * D
        cosh_, sinh_ = np.array([0.5 * math.exp(-h), 0.5 * math.exp(h), 0, 0]), np.array(
            [0.5 * math.exp(-h), -0.5 * math.exp(h), 0, 0])
        cos_, sin_ = np.array([0, 0, math.cos(h), math.sin(h)]), np.array([0, 0, -math.sin(h), math.cos(h)])
        if D < D_SWITCH:
            return SMALL_SCALE[:, None] * np.stack([(cosh_ + cos_) / 2, (sinh_ + sin_) / (2 * D),
                                                    (cosh_ - cos_) / D**2, (sinh_ - sin_) / D**3])
        return np.stack([np.array([0, 1.0, 0, 0]), np.array([math.exp(-D), 0, 0, 0]), cos_, sin_])
    a = D / SQRT2
    h = 0.5 * a
    E = {"cosh": np.array([0.5 * math.exp(-h), 0.5 * math.exp(h)]),
         "sinh": np.array([0.5 * math.exp(-h), -0.5 * math.exp(h)]),
         "lo": np.array([0.0, 1.0]), "hi": np.array([math.exp(-a), 0.0])}
    T = {"cos": np.array([math.cos(h), math.sin(h)]), "sin": np.array([-math.sin(h), math.cos(h)])}

    def prod(e: str, t: str) -> np.ndarray:
        """Paper-basis coefficients of (exponential part e) x (trigonometric part t)."""
        return np.outer(E[e], T[t]).ravel()

    if D < D_SWITCH:
        return SMALL_SCALE[:, None] * np.stack([
            prod("cosh", "cos"), (prod("cosh", "sin") + prod("sinh", "cos")) / (2 * a),
            prod("sinh", "sin") / a**2, (prod("cosh", "sin") - prod("sinh", "cos")) / (2 * a**3)])
    return np.stack([prod("lo", "cos"), prod("lo", "sin"), prod("hi", "cos"), prod("hi", "sin")])


# ---------------------------------------------------------------- time bases

def time_basis(tau: np.ndarray, m: np.ndarray | float, time_kind: str) -> np.ndarray:
    """Balanced end-interpolating time pair (phi0, phi1) at local segment time tau.

    tau : (..., F) float in [0, 1]; m : (...) float >= 0 (trig: m < pi). Returns (..., F, 2) float64 with
    phi0(0) = phi1(1) = 1, phi0(1) = phi1(0) = 0 exactly; m = 0 gives (1 - tau, tau) for both kinds.
    """
    tau = np.asarray(tau, dtype=np.float64)
    m = np.abs(np.asarray(m, dtype=np.float64))[..., None]
    if time_kind == "exp":
        phi1 = _sinh_ratio(tau, m)
        phi0 = _sinh_ratio(1.0 - tau, m)
    elif time_kind == "trig":
        if np.any(m >= np.pi):
            raise ParameterError("trig time constant must be below pi per segment")
        phi1 = tau * _sc(m * tau) / _sc(m)
        phi0 = (1.0 - tau) * _sc(m * (1.0 - tau)) / _sc(m)
    else:
        raise ParameterError(f"time kind must be one of {TIME_KINDS}, got {time_kind!r}")
    return np.stack([phi0, phi1], axis=-1)


def _sinh_ratio(tau: np.ndarray, m: np.ndarray) -> np.ndarray:
    """sinh(m tau) / sinh(m) without overflow, -> tau as m -> 0."""
    mm = np.maximum(m, 1e-300)
    big = np.exp(mm * (tau - 1.0)) * np.expm1(-2.0 * mm * tau) / np.expm1(-2.0 * mm)
    return np.where(m < 1e-12, tau, big)


def time_basis_paper(t: np.ndarray, m: np.ndarray | float, time_kind: str) -> np.ndarray:
    """The paper's time basis {e^{mt}, e^{-mt}} or {cos mt, sin mt}, (..., F, 2) (reference only)."""
    t = np.asarray(t, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)[..., None]
    if time_kind == "exp":
        return np.stack([np.exp(m * t), np.exp(-m * t)], axis=-1)
    return np.stack([np.cos(m * t), np.sin(m * t)], axis=-1)


def time_to_paper(m: float, time_kind: str, t0: float, t1: float) -> tuple[np.ndarray, float]:
    """(N (2, 2), m_global): phi_i((t - t0) / (t1 - t0)) = sum_a N[i, a] paper_a(t) with constant m_global."""
    m, dt = float(m), float(t1) - float(t0)
    if not m > 0 or not dt > 0:
        raise ParameterError("the paper's time basis is degenerate at m = 0 (the balanced one is linear)")
    mg = m / dt
    if time_kind == "exp":
        e0 = math.exp(mg * t0)
        phi1 = np.array([1.0 / e0, -e0]) / (2 * math.sinh(m))
        phi0 = np.array([-math.exp(-m) / e0, math.exp(m) * e0]) / (2 * math.sinh(m))
        return np.stack([phi0, phi1]), mg
    th0, ph = mg * t0, mg * t1
    phi1 = np.array([-math.sin(th0), math.cos(th0)]) / math.sin(m)
    phi0 = np.array([math.sin(ph), -math.cos(ph)]) / math.sin(m)
    return np.stack([phi0, phi1]), mg


def paper_coefficients(code: int, m: float, D: float, coef: np.ndarray, t0: float = 0.0,
                       t1: float = 1.0) -> tuple[float, float, np.ndarray]:
    """(m_global, D, c (8,)) in the paper's basis and ordering c1..c8 from balanced coefficients (2, 4)."""
    time_kind, space_kind = family_kinds(code)
    N, mg = time_to_paper(m, time_kind, t0, t1)
    M = space_to_paper(D, space_kind)
    return mg, float(D), (N.T @ np.asarray(coef, dtype=np.float64) @ M).ravel()


def evaluate_family(u: np.ndarray, tau: np.ndarray, code: int, m: np.ndarray | float, D: np.ndarray | float,
                    coef: np.ndarray) -> np.ndarray:
    """w(u, tau) = T(tau) C S(u)^T for one family in balanced form.

    u : (..., N); tau : (..., F); m, D : (...); coef : (..., 2, 4). Returns (..., F, N) float64.
    """
    time_kind, space_kind = family_kinds(code)
    T = time_basis(tau, m, time_kind)
    S = space_basis(u, D, space_kind)
    return np.einsum("...fi,...ik,...nk->...fn", T, np.asarray(coef, dtype=np.float64), S)


MU_TRIG_MAX = 0.95 * np.pi
"""Largest trig time constant per segment (sin m must stay away from 0 for the end-interpolating pair)."""


def time_pair(tau: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Elementwise signed time pair: tau and mu of the same shape (...), returns (..., 2) float64.

    mu > 0: exp with m = mu; mu < 0: trig with m = -mu (clipped below pi); mu = 0: linear.
    """
    tau, mu = np.broadcast_arrays(np.asarray(tau, dtype=np.float64), np.asarray(mu, dtype=np.float64))
    out = np.empty(tau.shape + (2,))
    trig = mu < 0
    if np.all(~trig):
        tt, me = tau, mu
        out[..., 1], out[..., 0] = _sinh_ratio(tt, me), _sinh_ratio(1.0 - tt, me)
        return out
    ex = ~trig
    te, me = tau[ex], mu[ex]
    out[ex, 1], out[ex, 0] = _sinh_ratio(te, me), _sinh_ratio(1.0 - te, me)
    tt, mt = tau[trig], np.clip(-mu[trig], 1e-150, MU_TRIG_MAX)
    inv = 1.0 / np.sin(mt)  # 0 < m < pi: sin m > 0, and sin(m tau) / sin(m) -> tau as m -> 0
    out[trig, 1], out[trig, 0] = np.sin(mt * tt) * inv, np.sin(mt * (1.0 - tt)) * inv
    return out
