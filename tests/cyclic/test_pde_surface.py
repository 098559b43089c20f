"""The analytic elliptic PDE patches: boundary curves reproduced exactly, the PDE satisfied, no overflow."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.cyclic.pde_surface import (
    PatchConditions,
    biharmonic_residual,
    fourier_modes,
    solve_patches,
)
from pdeanim.errors import ParameterError


def smooth_curves(n_curves: int, p: int, top_mode: int, seed: int) -> np.ndarray:
    """(1, n_curves, p, 3) random periodic curves with Fourier modes up to top_mode only."""
    rng = np.random.default_rng(seed)
    v = np.arange(p) * (2 * np.pi / p)
    n = np.arange(top_mode + 1)
    cos = rng.normal(size=(n_curves, top_mode + 1, 3)) / (1 + n[None, :, None]) ** 2
    sin = rng.normal(size=(n_curves, top_mode + 1, 3)) / (1 + n[None, :, None]) ** 2
    trig_c, trig_s = np.cos(np.outer(v, n)), np.sin(np.outer(v, n))
    return (np.einsum("pn,knc->kpc", trig_c, cos) + np.einsum("pn,knc->kpc", trig_s, sin))[None]


def test_fourier_modes_reconstruct_samples():
    rng = np.random.default_rng(1)
    for p in (7, 8):
        c = rng.normal(size=(p, 3))
        c0, cc, cs = fourier_modes(c)
        v = np.arange(p) * (2 * np.pi / p)
        n = np.arange(1, p // 2 + 1)
        back = c0 + np.cos(np.outer(v, n)) @ cc + np.sin(np.outer(v, n)) @ cs
        assert np.allclose(back, c, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(p=st.integers(5, 64), modes=st.integers(0, 19), a=st.floats(0.2, 1.5), seed=st.integers(0, 10_000),
       kind=st.sampled_from(["positions2", "hermite2", "positions3"]))
def test_boundary_curves_reproduced(p, modes, a, seed, kind):
    cond = {"positions2": PatchConditions.positions(2), "hermite2": PatchConditions.hermite(2),
            "positions3": PatchConditions.positions(3)}[kind]
    if cond.order > 2:  # N = 3 keeps 1e-9 for 0.7 <= a and a (M + 1) <= 15 (see pde_surface.MIN_A)
        a = max(a, 0.7)
        modes = min(modes, int(15 / a) - 1)
    curves = np.random.default_rng(seed).normal(size=(2, len(cond.u), p, 3))
    patches = solve_patches(curves, cond, modes=modes, a=a)
    v = np.arange(p) * (2 * np.pi / p)
    for b in range(2):
        for j, (uj, dj) in enumerate(zip(cond.u, cond.deriv, strict=True)):
            got = patches.evaluate(np.full(p, b), np.full(p, uj), v, du=dj)
            assert np.abs(got - curves[b, j]).max() < 1e-9


def test_biharmonic_satisfied_by_finite_differences():
    curves = smooth_curves(4, 32, 3, seed=3)
    patches = solve_patches(curves, modes=6)
    u = np.linspace(0.05, 0.95, 9)
    v = np.linspace(0.0, 6.0, 9)
    res, scale = biharmonic_residual(patches, 0, u, v, h=2e-3)
    assert np.abs(res).max() < 1e-4 * scale.max()
    assert scale.max() > 1.0  # the terms themselves are not trivially zero


@pytest.mark.parametrize("order", [2, 3])
def test_general_order_pde_satisfied_analytically(order):
    cond = PatchConditions.positions(order)
    patches = solve_patches(smooth_curves(2 * order, 24, 4, seed=order), cond, modes=8, a=0.8)
    q = 50
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 1, q), rng.uniform(0, 2 * np.pi, q)
    total, scale = np.zeros((q, 3)), np.zeros((q, 3))
    for k in range(order + 1):
        term = comb(order, k) * patches.a ** (2 * k) * patches.evaluate(
            np.zeros(q, int), u, v, du=2 * (order - k), dv=2 * k)
        total += term
        scale += np.abs(term)
    assert np.abs(total).max() < 1e-8 * scale.max()


def test_remainder_keeps_boundary_exact_with_few_modes():
    curves = np.random.default_rng(5).normal(size=(1, 4, 32, 3))
    low = solve_patches(curves, modes=2)
    v = np.arange(32) * (2 * np.pi / 32)
    for j, uj in enumerate((0.0, 1 / 3, 2 / 3, 1.0)):
        assert np.abs(low.evaluate(np.zeros(32, int), np.full(32, uj), v) - curves[0, j]).max() < 1e-9


def test_spine_passes_through_curve_centroids():
    curves = np.random.default_rng(6).normal(size=(3, 4, 20, 3))
    patches = solve_patches(curves, modes=5)
    for j, uj in enumerate((0.0, 1 / 3, 2 / 3, 1.0)):
        got = patches.spine(np.arange(3), np.full(3, uj))
        assert np.allclose(got, curves[:, j].mean(axis=1), atol=1e-12)


def test_many_modes_do_not_overflow():
    curves = np.random.default_rng(7).normal(size=(1, 4, 256, 3))
    patches = solve_patches(curves, modes=19, a=1.5)  # exponents up to the allowed 30
    pts, _, _ = patches.grid(10, 256)
    assert np.isfinite(pts).all()
    assert np.abs(pts[0, [0, 3, 6, 9]] - curves[0]).max() < 1e-9


def test_bad_input_raises():
    with pytest.raises(ParameterError):
        solve_patches(np.zeros((1, 3, 8, 3)))
    with pytest.raises(ParameterError):
        solve_patches(np.full((1, 4, 8, 3), np.nan))
    with pytest.raises(ParameterError):
        solve_patches(np.zeros((1, 4, 8, 3)), a=0.0)
    with pytest.raises(ParameterError):
        solve_patches(np.zeros((1, 4, 256, 3)), modes=127)
    with pytest.raises(ParameterError):
        solve_patches(np.zeros((1, 4, 8, 3)), PatchConditions((0.0, 0.0, 1.0, 1.0), (0, 0, 0, 1)))
