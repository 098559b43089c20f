"""The fast paths of the fit equal their plain definitions bit for bit (speed without changing results)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from pdeanim.clip import load_clip
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model import families as fam
from pdeanim.model.clipmodel import _SegmentTime
from pdeanim.model.fitcore import (
    SpaceStage,
    floor_distances,
    items_from_curves,
    items_to_vertices,
    model_distances,
    reconstruct_items,
    space_stage,
    time_stage,
    vertex_slots,
)
from pdeanim.model.segments import Segmentation, uniform_segmentation
from pdeanim.model.spacefit import captured_energy
from pdeanim.model.timefit import _dot4, segment_pair, sin_table
from pdeanim.poses import make_poses

MU_VALUES = [0.0, 1e-13, -1e-13, 1e-9, 0.2, 3.0, 32.0, 60.0, -0.3, -2.9, -3.0, -1e-9]


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 7), st.integers(2, 40))
def test_segment_pair_equals_time_pair(seed, n_segments, n_frames):
    """segment_pair (per-segment denominators, trig rows by a Taylor product) == elementwise time_pair:
    bit for bit on linear and exp rows, to 1e-14 on trig rows (sin_table instead of np.sin)."""
    rng = np.random.default_rng(seed)
    times = np.sort(rng.uniform(0, 5, n_frames))
    times[-1] += 1.0
    segm = uniform_segmentation(times, n_segments)
    mu = rng.choice(MU_VALUES, size=(13, segm.n_segments)) * rng.uniform(0.5, 1.0, (13, segm.n_segments))
    seg, tau = segm.frame_segment(), segm.frame_tau()
    ref = fam.time_pair(np.broadcast_to(tau, mu[:, seg].shape), mu[:, seg])
    p0, p1 = segment_pair(segm, mu)
    trig = mu[:, seg] < 0
    assert np.array_equal(p0[~trig], ref[..., 0][~trig]) and np.array_equal(p1[~trig], ref[..., 1][~trig])
    np.testing.assert_allclose(p0[trig], ref[..., 0][trig], rtol=0, atol=1e-14)
    np.testing.assert_allclose(p1[trig], ref[..., 1][trig], rtol=0, atol=1e-14)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 700), st.integers(1, 60))
def test_sin_table_equals_sin(seed, rows, cols):
    """The separable Taylor product (chunked matrix products) == np.sin of the outer product to 4e-15 (seen:
    2.03e-15 at m near MU_TRIG_MAX)."""
    rng = np.random.default_rng(seed)
    m = np.concatenate([rng.uniform(0, fam.MU_TRIG_MAX, rows), [0.0, 1e-150, fam.MU_TRIG_MAX, np.pi]])
    t = np.concatenate([rng.uniform(0, 1, cols), [0.0, 1.0]])
    np.testing.assert_allclose(sin_table(m, t), np.sin(m[:, None] * t[None, :]), rtol=0, atol=4e-15)


def test_segment_pair_single_frame_segmentation():
    segm = Segmentation(np.array([0, 0]), np.zeros(1))
    p0, p1 = segment_pair(segm, np.array([[0.0], [-1.0], [2.0]]))
    ref = fam.time_pair(np.zeros((3, 1)), np.array([[0.0], [-1.0], [2.0]]))
    assert np.array_equal(p0, ref[..., 0]) and np.array_equal(p1, ref[..., 1])


def test_dot4_equals_sum(rng):
    x, y = rng.normal(size=(50, 7, 4)), rng.normal(size=(50, 7, 4))
    assert np.array_equal(_dot4(x, y), (x * y).sum(-1))


def _random_curves(rng, n_vertices=60, n_points=7):
    order = rng.permutation(n_vertices)
    cuts = np.sort(rng.choice(np.arange(1, n_vertices), size=n_vertices // n_points - 1, replace=False))
    from pdeanim.curveset import CurveSet

    return CurveSet.from_lists(np.split(order, cuts))


def test_item_layout_round_trip_and_distances(rng):
    """Gather/scatter between vertices and padded items, and distances computed in item space, equal the
    plain definitions (moveaxis + boolean masks, np.linalg.norm in vertex space)."""
    curves = _random_curves(rng)
    idx, mask = curves.padded()
    values = rng.normal(size=(9, 60, 3))
    Y = items_from_curves(values, idx, mask)
    v = values[:, idx, :] * mask[None, :, :, None]
    assert np.array_equal(Y, np.moveaxis(v, 3, 2).reshape(9, -1, idx.shape[1]))
    assert np.array_equal(items_to_vertices(Y, idx, mask, 60), values)

    K, N = Y.shape[1:]
    u = np.where(mask, np.cumsum(mask, axis=1) / np.maximum(mask.sum(1, keepdims=True), 1), 0.0)
    space = space_stage(Y, np.repeat(u, 3, axis=0).reshape(K, N), np.repeat(mask, 3, axis=0))
    assert isinstance(space, SpaceStage)
    time = time_stage(space, uniform_segmentation(np.arange(9.0), 2))
    slots = vertex_slots(idx, mask, 60)
    R = items_to_vertices(reconstruct_items(space, time), idx, mask, 60)
    assert np.array_equal(model_distances(space, time, slots), np.linalg.norm(R - values, axis=-1))
    proj = np.moveaxis(space.b @ np.swapaxes(space.proj.U, 1, 2), 1, 0)
    floor = np.linalg.norm(items_to_vertices(Y - proj, idx, mask, 60), axis=-1)
    assert np.array_equal(floor_distances(space, slots), floor)


def test_captured_energy_shared_u_equals_per_item(rng):
    """The per-curve product (x, y, z sharing u) equals the per-item computation exactly."""
    C, N, F = 11, 8, 15
    u = np.sort(rng.uniform(0, 1, (C, N)), axis=1)
    mask = np.ones((C, N), bool)
    mask[0, 5:] = False
    Y = rng.normal(size=(3 * C, F, N)) * np.repeat(mask, 3, axis=0)[:, None, :]
    gram = np.swapaxes(Y, 1, 2) @ Y
    for kind in fam.SPACE_KINDS:
        D = rng.uniform(0, 8, C)
        shared = captured_energy(u, mask, gram, D, kind, per_curve=3)
        per_item = captured_energy(np.repeat(u, 3, 0), np.repeat(mask, 3, 0), gram, np.repeat(D, 3), kind)
        assert np.array_equal(shared, per_item)


def test_segment_sum_matches_one_hot_product(rng):
    from pdeanim.model.timefit import _segment_sum

    for segm in (uniform_segmentation(np.arange(23.0), 4), Segmentation(np.array([0, 0]), np.zeros(1)),
                 Segmentation(np.array([0, 3, 4, 9]), np.linspace(0, 1, 10))):
        values = rng.normal(size=(6, len(segm.t)))
        onehot = np.eye(segm.n_segments)[segm.frame_segment()]
        np.testing.assert_allclose(_segment_sum(values, segm), values @ onehot, rtol=1e-13, atol=1e-13)


def test_pinv_sym_cholesky_path_matches_eigh(rng):
    """Well-conditioned Gram matrices: Cholesky inverse == eigh pseudo-inverse to rounding; rank-deficient
    or ill-conditioned ones take the eigh path itself (identical)."""
    from pdeanim.model.spacefit import _pinv_eigh, _pinv_sym

    u = np.sort(rng.uniform(0, 1, (300, 12)), axis=1)
    mask = np.ones((300, 12))
    mask[:50, 3:] = 0  # rank 3
    S = fam.space_basis(u, rng.uniform(0, 10, 300), "D0") * mask[..., None]
    M = np.swapaxes(S, 1, 2) @ S
    M[60] = 0.0
    M[61] = np.diag([1.0, 1.0, 1.0, 1e-9])  # cond 1e9: eigh path
    a, b = _pinv_eigh(M), _pinv_sym(M)
    assert np.array_equal(a[:50], b[:50]) and np.array_equal(a[60:62], b[60:62])
    np.testing.assert_allclose(b[62:], a[62:], rtol=1e-8, atol=1e-10 * np.abs(a[62:]).max())


@pytest.fixture(scope="module")
def small_clip(morph_small, short_curves):
    """A 3-segment clip of the first 15 frames of the morph sphere (loaded for evaluation)."""
    poses = make_poses(morph_small.vertices[:15], morph_small.faces, morph_small.times[:15])
    parts = fit_poses(poses, FitOptions(segments=3), curves=short_curves)
    return load_clip(parts.topology, parts.coefficients)


def _plain_frame(clip, t: float) -> np.ndarray:
    """A frame from the definitions: per value, time_pair of its item times (space basis . knots), or the
    natural spline of the knot values for items on it (scipy's)."""
    coef, topo = clip.coef, clip.topo
    tw = min(max(t, 0.0), 1.0) if not clip.looping else t - np.floor(t)
    st = np.asarray(coef.segment_t, np.float64)
    s = int(np.clip(np.searchsorted(st, tw, side="right") - 1, 0, len(st) - 2))
    tau = np.clip((tw - st[s]) / (st[s + 1] - st[s]), 0.0, 1.0)
    cid, _ = topo.curves.curve_of_vertex(clip.n_vertices)
    code = coef.family[s][cid].astype(np.int64)  # (V, 3)
    mu = np.where(code >= 2, -1.0, 1.0) * coef.m[s][cid].astype(np.float64)
    u, D = np.broadcast_to(topo.u.astype(np.float64), (clip.n_vertices, 3)), coef.D[cid].astype(np.float64)
    B = np.zeros((clip.n_vertices, 3, 4))
    for kind in (0, 1):
        sel = code % 2 == kind
        B[sel] = fam.space_basis(u[sel][:, None], D[sel], fam.SPACE_KINDS[kind])[:, 0, :]
    P = [(B * coef.knots[j][cid].astype(np.float64)).sum(-1) for j in range(len(st))]
    phi = fam.time_pair(np.full(mu.shape, tau), mu)
    value = phi[..., 0] * P[s] + phi[..., 1] * P[s + 1]
    on = coef.spline_items()[cid]
    if on.any():  # docs/format.md §3.5: the natural cubic spline through the knot values
        spline = CubicSpline(st, np.stack(P), bc_type="natural")
        value = np.where(on, spline(st[s] + tau * (st[s + 1] - st[s])), value)
    return topo.rest.astype(np.float64) + value


@pytest.mark.parametrize("t", [0.0, 0.13, 1 / 3, 0.5, 0.77, 1.0, -0.2, 1.4])
def test_clip_frame_equals_plain_definition(small_clip, t):
    """The precomputed single-frame path (Python locate, grouped time pair, one gather) == the definition."""
    fast = small_clip.evaluate(t)
    ref = _plain_frame(small_clip, t)
    scale = np.abs(ref).max()
    assert fast.dtype == np.float32 and fast.shape == ref.shape
    np.testing.assert_allclose(fast, ref, rtol=0, atol=2e-6 * scale)
    np.testing.assert_array_equal(fast, small_clip.evaluate(np.array([t]))[0])  # scalar path == batch path
    np.testing.assert_array_equal(fast, small_clip.evaluate(np.float64(t)))


def test_looping_clip_frame_equals_plain_definition(morph_small, short_curves):
    """Looping clips wrap t in the single-frame path exactly as the definition does."""
    poses = make_poses(morph_small.vertices[:15], morph_small.faces, morph_small.times[:15])
    parts = fit_poses(poses, FitOptions(segments=3, loop=True), curves=short_curves)
    clip = load_clip(parts.topology, parts.coefficients)
    for t in (-0.3, 0.41, 1.0, 1.7):
        ref = _plain_frame(clip, t)
        np.testing.assert_allclose(clip.evaluate(t), ref, rtol=0, atol=2e-6 * np.abs(ref).max())


def test_segment_time_pair_equals_time_pair():
    """_SegmentTime.pair (grouped exp | trig | linear, precomputed denominators) == time_pair to float32."""
    rng = np.random.default_rng(7)
    mu = rng.choice(MU_VALUES, size=97) * rng.uniform(0.5, 1.0, 97)
    seg = _SegmentTime(mu)
    for tau in (0.0, 1e-7, 0.25, 0.5, 0.9, 1.0):
        got = seg.pair(tau)
        ref = fam.time_pair(np.full(mu.shape, tau), mu)
        assert got.shape == (2, 97) and got.dtype == np.float32
        np.testing.assert_allclose(got, ref.T.astype(np.float32), rtol=0, atol=4e-7)
    np.testing.assert_array_equal(seg.pair(0.0), np.stack([np.ones(97), np.zeros(97)]))
    np.testing.assert_array_equal(seg.pair(1.0), np.stack([np.zeros(97), np.ones(97)]))


def test_clip_evaluation_is_thread_safe(small_clip):
    """Per-thread scratch: frames evaluated concurrently equal the same frames evaluated serially."""
    ts = np.linspace(0, 1, 24)
    serial = [small_clip.evaluate(float(t)) for t in ts]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(lambda t: small_clip.evaluate(float(t)), ts))
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a, b)


def test_projection_fallback_equals_separate_condition_check(rng):
    """project_items(fallback=True) (condition numbers from the projection SVD) == the separate check of
    search_D (_well_conditioned, its own SVD) followed by a plain projection: same kinds, D and bases."""
    from pdeanim.model.spacefit import _well_conditioned, project_items

    K, N = 60, 9
    u = np.sort(rng.uniform(0, 1, (K, N)), axis=1)
    u[::4] = 0.5 + 1e-3 * u[::4]  # clustered points: ill-conditioned unless D = 0 is also
    mask = np.ones((K, N), bool)
    mask[1, 3:] = False  # a short curve (3 points)
    kind_i = rng.integers(0, 2, K)
    D = rng.uniform(0, 48, K).astype(np.float32).astype(np.float64)
    D[::5] = 0.0
    zeros = np.zeros(K)
    D2, kind2, _ = _well_conditioned(u, mask, None, kind_i, D, zeros, zeros, fam.SPACE_KINDS)
    assert np.any(D2 != D)  # the fall-back is exercised
    plain = project_items(u, mask, kind2, D2)
    fast = project_items(u, mask, kind_i, D, fallback=True)
    assert np.array_equal(fast.kind, plain.kind) and np.array_equal(fast.D, plain.D)
    assert np.array_equal(fast.U, plain.U) and np.array_equal(fast.to_coef, plain.to_coef)


def test_predict_equals_broadcast_form(rng):
    """predict (np.take gathers, in-place products) == the one-line broadcast definition, bit for bit."""
    from pdeanim.model.timefit import predict

    segm = Segmentation(np.array([0, 3, 4, 9]), np.linspace(0, 1, 10))
    z = rng.normal(size=(7, 4, 4))
    mu = rng.choice(np.array(MU_VALUES), size=(7, 3))
    seg = segm.frame_segment()
    p0, p1 = segment_pair(segm, mu)
    assert np.array_equal(predict(z, segm, mu), p0[..., None] * z[:, seg] + p1[..., None] * z[:, seg + 1])
