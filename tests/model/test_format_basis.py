"""Knots on a shared time basis (docs/format.md §3.4): weights on a few shared time tracks plus residual
tracks where that is smaller (morph blends), every knot within half a step as in plain tracks, bit-exact
decoding, plain tracks written otherwise, clear errors on broken parts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.curveset import CurveSet
from pdeanim.errors import ClipFormatError
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model import knotbasis
from pdeanim.model.clipformat import (
    CoefficientData,
    decode_coefficients,
    encode_coefficients,
    encode_topology,
)
from pdeanim.poses import make_poses


def _topology(rng: np.random.Generator, n_curves: int = 6, points: int = 5) -> bytes:
    V = n_curves * points
    order = rng.permutation(V).astype(np.int32)
    offsets = (np.arange(n_curves + 1) * points).astype(np.int32)
    u = np.zeros((V, 3), np.float32)
    u[order] = np.tile(np.linspace(0, 1, points), n_curves)[:, None]
    rest = rng.normal(size=(V, 3)).astype(np.float32)
    return encode_topology(CurveSet(order, offsets), u, np.zeros((0, 3), np.int32), rest, "chord",
                           tolerance=1e-6)


def _data(knots: np.ndarray, loop: bool = False, m: float = 0.0) -> CoefficientData:
    S1, C = knots.shape[:2]
    S = S1 - 1
    return CoefficientData(np.linspace(0, 1, S1), np.arange(S1) / 24.0, np.zeros((S, C, 3), np.uint8),
                           np.full((S, C, 3), m, np.float32), np.full((C, 3), 2.0, np.float32),
                           knots.astype(np.float32), "displacement", loop, {})


def _blend(rng: np.random.Generator, S1: int, C: int, rank: int = 2) -> np.ndarray:
    """Knots (S1, C, 3, 4) that are exactly a blend of ``rank`` shapes with smooth weights."""
    t = np.linspace(0, 1, S1)
    weights = np.stack([np.sin((j + 1) * np.pi * t + j) for j in range(rank)])  # (r, S1)
    shapes = rng.normal(size=(rank, C, 3, 4))
    return np.einsum("js,jcwk->scwk", weights, shapes)


def _positions(topology: bytes, coefficients: bytes) -> np.ndarray:
    clip = load_clip(topology, coefficients)
    return clip.evaluate(np.linspace(0, 1, 41)).astype(np.float64)


def test_a_blend_is_stored_on_a_basis_within_the_budget_and_smaller():
    rng = np.random.default_rng(3)
    topo = _topology(rng)
    data = _data(_blend(rng, 40, 6))
    budget = 1e-3
    v3 = encode_coefficients(topo, data, knot_rms=budget)
    v2 = encode_coefficients(topo, data, knot_rms=budget, shared_basis=False)
    h3, a3 = container.unpack(v3)
    assert h3["knot_rank"] == 2 and h3["knot_differences"] in (1, 2)
    assert set(a3) >= {"knot_weights", "knot_basis", "knot_step", "knots"}
    assert container.unpack(v2)[0]["knot_rank"] == 0 and "knot_basis" not in container.unpack(v2)[1]
    assert len(v3) < 0.7 * len(v2)  # header and time arrays included: the knots alone shrink far more
    exact = _positions(topo, encode_coefficients(topo, data, tolerance=1e-9, shared_basis=False))
    d = np.linalg.norm(_positions(topo, v3) - exact, axis=-1)
    d2 = np.linalg.norm(_positions(topo, v2) - exact, axis=-1)
    assert np.sqrt(np.mean(d * d)) <= 1.5 * np.sqrt(np.mean(d2 * d2))  # rounded as finely as plain tracks
    assert d.max() <= 4 * budget  # the knots' cap (4 x the budget) holds


def test_knots_without_low_rank_structure_stay_plain_byte_for_byte():
    rng = np.random.default_rng(4)
    topo = _topology(rng)
    data = _data(rng.normal(size=(12, 6, 3, 4)))
    v3 = encode_coefficients(topo, data, knot_rms=1e-4)
    assert v3 == encode_coefficients(topo, data, knot_rms=1e-4, shared_basis=False)
    # a max target (a tolerance per coordinate) uses the basis too: the steps are the same
    blend = _data(_blend(rng, 30, 6))
    h, a = container.unpack(encode_coefficients(topo, blend, tolerance=1e-4))
    h2, a2 = container.unpack(encode_coefficients(topo, blend, tolerance=1e-4, shared_basis=False))
    assert h["knot_rank"] > 0 and h2["knot_rank"] == 0
    np.testing.assert_array_equal(a["knot_step"], a2["knot_step"])


def test_a_looping_clip_keeps_its_first_and_last_knots_equal():
    rng = np.random.default_rng(5)
    topo = _topology(rng)
    knots = _blend(rng, 33, 6)
    knots[-1] = knots[0]
    blob = encode_coefficients(topo, _data(knots, loop=True), knot_rms=1e-3)
    h, a = container.unpack(blob)
    assert h["knot_rank"] > 0
    coef = decode_coefficients(h, a, 6)
    np.testing.assert_array_equal(coef.knots[0], coef.knots[-1])


@settings(max_examples=25, deadline=None)
@given(rank=st.integers(1, 6), S1=st.integers(2, 30), C=st.integers(1, 5), seed=st.integers(0, 10**6))
def test_decoding_is_the_specified_float64_sum(rank, S1, C, seed):
    """knots = float32(sum over j ascending of (q * h) * basis[j, s], then + p * h) in doubles."""
    rng = np.random.default_rng(seed)
    r = min(rank, S1)
    codes = rng.integers(-(2**28), 2**28, (r, C, 3, 4))
    residual = rng.integers(-(2**10), 2**10, (S1, C, 3, 4))
    steps = (2.0 ** rng.integers(-30, 0, (C, 3))).astype(np.float32)
    basis = rng.normal(size=(r, S1)).astype(np.float32)
    got = knotbasis.knots_from_basis(codes, residual, steps, basis)
    for s in range(S1):
        for c in range(C):
            for w in range(3):
                for k in range(4):
                    acc, h = 0.0, float(steps[c, w])
                    for j in range(r):
                        acc += (float(codes[j, c, w, k]) * h) * float(basis[j, s])
                    acc += float(residual[s, c, w, k]) * h
                    assert got[s, c, w, k] == np.float32(acc)


@settings(max_examples=20, deadline=None)
@given(scale=st.floats(1e-3, 1e3), tol=st.floats(1e-5, 1e-2), rank=st.integers(1, 3), noise=st.floats(0, 1),
       seed=st.integers(0, 10**6))
def test_every_knot_stays_within_half_a_step_at_any_scale(scale, tol, rank, noise, seed):
    """Low-rank knots with any amount of noise, at any scale: the stored knots (basis or not) lie within half
    a step of the exact ones, so the bound of plain tracks holds per vertex coordinate."""
    rng = np.random.default_rng(seed)
    topo = _topology(rng)
    knots = (_blend(rng, 24, 6, rank) + noise * rng.normal(size=(24, 6, 3, 4))) * scale
    data = _data(knots)
    h, a = container.unpack(encode_coefficients(topo, data, tolerance=tol * scale))
    coef = decode_coefficients(h, a, 6)
    half = a["knot_step"].astype(np.float64)[None, :, :, None] / 2
    err = np.abs(coef.knots.astype(np.float64) - knots)
    assert np.all(err <= half * (1 + 1e-6) + 1e-7 * np.abs(knots))  # + float32 rounding of the knots


def _edit(blob: bytes, header: dict | None = None, drop: str | None = None, **arrays) -> bytes:
    h, a = container.unpack(blob)
    a = {k: v for k, v in {**a, **arrays}.items() if k != drop}
    return container.pack({**h, **(header or {})}, a)


def test_broken_basis_parts_raise_clear_errors():
    rng = np.random.default_rng(6)
    topo = _topology(rng)
    blob = encode_coefficients(topo, _data(_blend(rng, 20, 6)), knot_rms=1e-3)
    h, a = container.unpack(blob)
    assert h["knot_rank"] > 0
    r, S1 = a["knot_basis"].shape
    bad_basis = a["knot_basis"].copy()
    bad_basis[0, 0] = np.inf
    cases = [
        (_edit(blob, {"knot_differences": 3}), "knot_differences must be 1 or 2"),
        (_edit(blob, drop="knots"), "no 'knots'"),
        (_edit(blob, {"knot_rank": 0}), "knot_rank 0 must not hold"),
        (_edit(blob, {"knot_rank": -1}), "knot_rank must be an integer"),
        (_edit(blob, {"knot_rank": S1 + 1}), "knot_rank must be an integer"),
        (_edit(blob, {"knot_rank": True}), "knot_rank must be an integer"),
        (_edit(blob, {"knot_rank": None}), "knot_rank must be an integer"),
        (_edit(blob, {"knot_rank": r + 1}), "'knot_weights' has shape"),
        (_edit(blob, knot_basis=a["knot_basis"][:, :-1]), "'knot_basis' has shape"),
        (_edit(blob, knot_basis=a["knot_basis"].astype(np.float64)), "'knot_basis' has dtype"),
        (_edit(blob, knot_weights=a["knot_weights"].astype(np.int32)), "'knot_weights' has dtype"),
        (_edit(blob, knot_basis=bad_basis), "non-finite"),
        (_edit(blob, knot_basis=np.full_like(a["knot_basis"], 3e38)), "non-finite"),
        (_edit(blob, knot_step=-a["knot_step"]), "knot steps must be positive"),
        (_edit(blob, drop="knot_basis"), "no 'knot_basis'"),
    ]
    for broken, match in cases:
        with pytest.raises(ClipFormatError, match=match):
            decode_coefficients(*container.unpack(broken), 6)


def test_a_fit_of_a_morph_blend_uses_the_basis_and_meets_its_target(morph_small, short_curves):
    """AnimatedMorphSphere is a blend of two targets: its knots need a rank-2 or 3 basis."""
    poses = make_poses(morph_small.vertices[:40], morph_small.faces, morph_small.times[:40])
    three = fit_poses(poses, FitOptions(target_rel_rms=1e-3), curves=short_curves)
    h = container.unpack(three.coefficients)[0]
    assert 1 <= h["knot_rank"] <= 3
    assert three.report["target_met"] and three.report["rel_rms"] <= 1e-3
    clip = load_clip(three.topology, three.coefficients)  # the report is the stored clip's error
    d = np.linalg.norm(clip.evaluate(clip.frame_t()).astype(np.float64) - poses.vertices, axis=-1)
    assert np.sqrt(np.mean(d * d)) == pytest.approx(three.report["rms"], rel=1e-6)
