"""The four closed-form families: PDE satisfied, balanced = paper basis, coefficient recovery."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.errors import ParameterError
from pdeanim.model import families as fam


def _fd4(f, u, h):
    return (f(u - 2 * h) - 4 * f(u - h) + 6 * f(u) - 4 * f(u + h) + f(u + 2 * h)) / h**4


def _fd2(f, t, h):
    return (f(t - h) - 2 * f(t) + f(t + h)) / h**2


@pytest.mark.parametrize("code", [0, 1, 2, 3])
@pytest.mark.parametrize("D", [0.7, 2.5, 6.0])
def test_each_family_satisfies_its_pde(code, D):
    """w_tt / w_uuuu is the constant +-m^2 / D^4 of the family (finite differences)."""
    m = 1.3
    tk, sk = fam.family_kinds(code)
    rng = np.random.default_rng(code)
    coef = rng.normal(size=(2, 4))

    def w(u, t):
        return fam.evaluate_family(np.atleast_1d(u), np.atleast_1d(t), code, m, D, coef)[0, 0]

    u0, t0 = 0.37, 0.41
    wtt = _fd2(lambda t: w(u0, t), t0, 1e-3)
    wuuuu = _fd4(lambda u: w(u, t0), u0, min(0.01, 0.04 / D))
    w0 = w(u0, t0)
    sign_t = 1.0 if tk == "exp" else -1.0
    sign_s = 1.0 if sk == "D0" else -1.0
    assert wtt == pytest.approx(sign_t * m**2 * w0, rel=1e-4, abs=1e-6)
    assert wuuuu == pytest.approx(sign_s * D**4 * w0, rel=2e-3, abs=1e-4 * D**4)
    assert wtt / wuuuu == pytest.approx(sign_t * sign_s * m**2 / D**4, rel=3e-3)


@pytest.mark.parametrize("kind", fam.SPACE_KINDS)
@pytest.mark.parametrize("D", [0.05, 0.9, 3.99, 4.0, 11.0, 30.0])
def test_balanced_space_basis_equals_paper_map(kind, D):
    u = np.linspace(0, 1, 41)
    B = fam.space_basis(u, D, kind)
    P = fam.space_basis_paper(u, D, kind)
    M = fam.space_to_paper(D, kind)
    scale = np.abs(M).max() * np.abs(P).max()
    assert np.abs(B - P @ M.T).max() <= 1e-12 * max(scale, 1.0)


@pytest.mark.parametrize("kind", fam.SPACE_KINDS)
def test_space_basis_tends_to_cubics(kind):
    u = np.linspace(0, 1, 11)
    s = u - 0.5
    cubic = np.stack([np.ones_like(s), 2 * s, 4 * s**2, 8 * s**3], axis=-1)
    assert np.abs(fam.space_basis(u, 0.0, kind) - cubic).max() < 1e-15
    assert np.abs(fam.space_basis(u, 1e-5, kind) - cubic).max() < 1e-8


def test_large_D_does_not_overflow():
    u = np.linspace(0, 1, 101)
    for kind in fam.SPACE_KINDS:
        B = fam.space_basis(u, 5000.0, kind)
        assert np.all(np.isfinite(B)) and np.abs(B).max() <= 1.0 + 1e-12
    T = fam.time_basis(np.linspace(0, 1, 9), 2000.0, "exp")
    assert np.all(np.isfinite(T)) and T.max() <= 1.0 + 1e-12


@settings(max_examples=40, deadline=None)
@given(m=st.floats(0.0, 60.0), tau=st.floats(0.0, 1.0), kind=st.sampled_from(fam.TIME_KINDS))
def test_time_pair_interpolates_ends(m, tau, kind):
    """phi0/phi1 are 1/0 at the ends exactly and finite in between, for every m."""
    if kind == "trig":
        m = m % 3.0
    T = fam.time_basis(np.array([0.0, tau, 1.0]), m, kind)
    assert np.all(np.isfinite(T))
    assert T[0, 0] == 1.0 and T[0, 1] == 0.0 and T[2, 0] == 0.0 and T[2, 1] == 1.0


@settings(max_examples=30, deadline=None)
@given(m=st.floats(0.05, 3.0), t0=st.floats(0.0, 0.5), dt=st.floats(0.1, 0.5),
       kind=st.sampled_from(fam.TIME_KINDS))
def test_time_map_to_paper_is_exact(m, t0, dt, kind):
    t = np.linspace(t0, t0 + dt, 7)
    N, mg = fam.time_to_paper(m, kind, t0, t0 + dt)
    bal = fam.time_basis((t - t0) / dt, m, kind)
    pap = fam.time_basis_paper(t, mg, kind)
    assert np.abs(bal - pap @ N.T).max() < 1e-9 * max(1.0, np.abs(N).max() * np.abs(pap).max())


def test_time_pair_signed_matches_kinds():
    tau = np.linspace(0, 1, 5)
    np.testing.assert_allclose(fam.time_pair(tau, np.full(5, 1.5)), fam.time_basis(tau, 1.5, "exp"))
    np.testing.assert_allclose(fam.time_pair(tau, np.full(5, -1.5)), fam.time_basis(tau, 1.5, "trig"))
    np.testing.assert_allclose(fam.time_pair(tau, np.zeros(5)), np.stack([1 - tau, tau], -1))


@pytest.mark.parametrize("code", [0, 1, 2, 3])
def test_fit_recovers_known_coefficients(code):
    """Noise-free data from a family: least squares (QR) recovers its 8 coefficients to ~1e-9."""
    rng = np.random.default_rng(7 + code)
    u, tau = np.linspace(0, 1, 30), np.linspace(0, 1, 12)
    m, D = 1.7, 5.5
    coef = rng.normal(size=(2, 4))
    W = fam.evaluate_family(u, tau, code, m, D, coef)
    tk, sk = fam.family_kinds(code)
    A = np.kron(fam.time_basis(tau, m, tk), fam.space_basis(u, D, sk))  # rows (f, n), cols (i, k)
    sol, *_ = np.linalg.lstsq(A, W.ravel(), rcond=None)
    np.testing.assert_allclose(sol.reshape(2, 4), coef, atol=1e-9)
    mg, _, c8 = fam.paper_coefficients(code, m, D, coef)
    ref = np.einsum("fa,ab,nb->fn", fam.time_basis_paper(tau, mg, tk), c8.reshape(2, 4),
                    fam.space_basis_paper(u, D, sk))
    np.testing.assert_allclose(ref, W, atol=1e-9)


def test_family_codes_round_trip_and_reject_bad():
    for code in range(4):
        assert fam.family_code(*fam.family_kinds(code)) == code
    with pytest.raises(ParameterError):
        fam.family_kinds(4)
    with pytest.raises(ParameterError):
        fam.space_basis(np.zeros(3), 1.0, "D2")
    with pytest.raises(ParameterError):
        fam.space_to_paper(0.0, "D0")
