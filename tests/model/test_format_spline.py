"""The natural-spline time model (docs/format.md §3.5): its tangents, its fit, its evaluation and the choice
between it and the paper's time pairs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.errors import ClipFormatError
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.fit.heldout import heldout_comparison
from pdeanim.model import clipmodel
from pdeanim.model.clipformat import TIME_SPLINE, decode_coefficients, encode_coefficients
from pdeanim.model.segments import Segmentation
from pdeanim.model.simplecurves import simple_curves
from pdeanim.model.spline import (
    natural_tangents,
    predict_spline,
    prefer_spline,
    solve_spline_knots,
    spline_design,
    spline_weight_bound,
)
from tests.conformance.generate import _synthetic_blend, _synthetic_dynamic
from tests.model.test_inbetween import synthetic


def _times(rng: np.random.Generator, n: int) -> np.ndarray:
    """n strictly increasing times from 0 to 1 (uneven)."""
    gaps = rng.uniform(0.2, 1.0, n - 1)
    return np.concatenate([[0.0], np.cumsum(gaps) / gaps.sum()])


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 30), st.integers(0, 2**32 - 1))
def test_tangents_and_design_are_scipys_natural_spline(n_knots, seed):
    """The Thomas solve gives CubicSpline(bc_type="natural")'s knot slopes, and the design its values."""
    rng = np.random.default_rng(seed)
    t = _times(rng, n_knots)
    P = rng.normal(size=(n_knots, 3, 2))
    ref = CubicSpline(t, P, bc_type="natural")
    scale = 1 + np.abs(P).max()
    np.testing.assert_allclose(natural_tangents(P, t), ref.derivative()(t), atol=1e-9 * scale)
    x = rng.uniform(0, 1, 40)
    seg = np.clip(np.searchsorted(t, x, side="right") - 1, 0, n_knots - 2)
    tau = (x - t[seg]) / (t[seg + 1] - t[seg])
    W = spline_design(t, seg, tau)
    np.testing.assert_allclose(np.einsum("nj,jab->nab", W, P), ref(x), atol=1e-10 * scale)
    np.testing.assert_allclose(W.sum(1), 1.0, atol=1e-12)  # constants are reproduced


@settings(max_examples=20, deadline=None)
@given(st.integers(2, 40), st.integers(0, 2**32 - 1))
def test_a_knot_at_every_frame_solves_to_the_frames(n_frames, seed):
    """With every frame a knot the spline design is the identity: the knots are the frames, as the dense QR
    least squares of that design gives them (the solve skips it)."""
    rng = np.random.default_rng(seed)
    t = _times(rng, n_frames)
    segm = Segmentation(np.arange(n_frames), t)
    W = spline_design(segm.segment_t, segm.frame_segment(), segm.frame_tau())
    np.testing.assert_allclose(W, np.eye(n_frames), atol=1e-12)
    b = rng.normal(size=(5, n_frames, 4))
    np.testing.assert_array_equal(solve_spline_knots(b, segm), b)


def test_two_knots_give_the_straight_line_and_zero_length_segments_are_refused():
    t = np.array([0.0, 1.0])
    np.testing.assert_allclose(natural_tangents(np.array([1.0, 3.0]), t), [2.0, 2.0])
    assert spline_weight_bound(t, np.linspace(0, 1, 11)) == pytest.approx(1.0)
    with pytest.raises(Exception, match="strictly increasing"):
        natural_tangents(np.zeros(3), np.array([0.0, 0.5, 0.5]))


@settings(max_examples=30, deadline=None)
@given(st.integers(4, 30), st.data())
def test_spline_knots_are_the_least_squares_solution(n_frames, data):
    """The QR solve equals lstsq of the dense design, for any segmentation and uneven frame times."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    t = _times(rng, n_frames)
    inner = data.draw(st.lists(st.integers(1, n_frames - 2), max_size=n_frames - 2, unique=True))
    segm = Segmentation(np.array(sorted([0, n_frames - 1, *inner]), np.int64), t)
    b = rng.normal(size=(3, n_frames, 4))
    z = solve_spline_knots(b, segm)
    A = spline_design(segm.segment_t, segm.frame_segment(), segm.frame_tau())
    ref = np.linalg.lstsq(A, np.moveaxis(b, 1, 0).reshape(n_frames, -1), rcond=None)[0]
    scale = 1 + np.abs(ref).max()
    np.testing.assert_allclose(z, np.moveaxis(ref.reshape(-1, 3, 4), 1, 0), atol=1e-8 * scale)
    np.testing.assert_allclose(predict_spline(z, segm),
                               np.moveaxis((A @ ref).reshape(n_frames, 3, 4), 1, 0), atol=1e-9 * scale)


def test_spline_candidates():
    """Smooth motion is a candidate, static items are not; too few frames give none."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 1, 40)
    smooth = np.sin(2 * np.pi * 1.5 * t)[None, :, None] * np.ones((1, 1, 4))
    b = np.concatenate([smooth, rng.normal(size=(1, 40, 4)), np.zeros((1, 40, 4))])
    choice = prefer_spline(b, t)
    assert choice[0] and not choice[2]
    assert not prefer_spline(b[:, :3], t[:3]).any()


def _spline_parts(blend: bool = False):
    make = (_synthetic_blend("absolute", "chord", False, spline=True) if blend
            else _synthetic_dynamic("displacement", "chord", False, spline=True))
    return make()


def _definition(clip, t: float) -> np.ndarray:
    """A frame of a clip with spline items from the spec's formulas in float64, straight from the decoded
    knots."""
    coef = clip.coef
    seg_t = np.asarray(coef.segment_t, np.float64)
    S = len(seg_t) - 1
    t = min(max(t, 0.0), 1.0)
    s = int(min(max(np.searchsorted(seg_t, t, side="right") - 1, 0), S - 1))
    tau = (t - seg_t[s]) / (seg_t[s + 1] - seg_t[s])
    P = clip._knot_fields.astype(np.float64)  # (S+1, V*3): the knot fields of §3.6
    T = CubicSpline(seg_t, P, bc_type="natural").derivative()(seg_t)
    h00, h01 = (1 + 2 * tau) * (1 - tau) ** 2, tau**2 * (3 - 2 * tau)
    h10, h11 = tau * (1 - tau) ** 2, tau**2 * (tau - 1)
    d = seg_t[s + 1] - seg_t[s]
    cubic = h00 * P[s] + h01 * P[s + 1] + d * (h10 * T[s] + h11 * T[s + 1])
    base = clip._base_flat.astype(np.float64)
    plain = clipmodel.DynamicClip._frame(clip, s, tau).astype(np.float64).ravel()  # pair values elsewhere
    out = plain.copy()
    i = clip._cubic_values[s]
    if i is not None:
        out[i] = cubic[i] + base[i]
    return out.reshape(-1, 3)


@pytest.mark.parametrize("blend", [False, True])
def test_spline_round_trip_and_the_spec_definition(blend):
    """Time models decode unchanged and the evaluator equals the spec's spline formulas (scipy's natural
    spline of the knot fields)."""
    parts = _spline_parts(blend)
    header, arrays = container.unpack(parts.coefficients)
    assert (header["knot_rank"] >= 1) == blend
    data = decode_coefficients(header, arrays, header["n_curves"])
    assert 0 < data.spline_items().sum() < data.spline_items().size
    clip = load_clip(parts.topology, parts.coefficients)
    assert clip._tangent_fields is not None
    ts = np.linspace(-0.1, 1.1, 49)
    fast = clip.evaluate(ts)
    scale = np.abs(fast).max()
    for k, t in enumerate(ts):
        np.testing.assert_allclose(fast[k], _definition(clip, float(t)), atol=2e-6 * scale, rtol=0)


def test_numpy_fallback_equals_compiled_spline_path(monkeypatch):
    parts = _spline_parts()
    compiled = load_clip(parts.topology, parts.coefficients).evaluate(np.linspace(0, 1, 23))
    monkeypatch.setattr(clipmodel, "COMPILED", False)
    plain = load_clip(parts.topology, parts.coefficients)
    np.testing.assert_array_equal(plain.evaluate(np.linspace(0, 1, 23)), compiled)


def test_spline_items_refuse_zero_length_segments_nonzero_constants_and_bad_models():
    parts = _spline_parts()
    header, arrays = container.unpack(parts.coefficients)
    seg = arrays["segment_t"].copy()
    seg[2] = seg[1]
    with pytest.raises(ClipFormatError, match="strictly increasing"):
        load_clip(parts.topology, container.pack(header, {**arrays, "segment_t": seg}))
    with pytest.raises(ClipFormatError, match="time_model must be 0"):
        doubled = {**arrays, "time_model": arrays["time_model"] * 2}
        load_clip(parts.topology, container.pack(header, doubled))
    with pytest.raises(ClipFormatError, match="no 'time_model'"):
        without = {k: v for k, v in arrays.items() if k != "time_model"}
        load_clip(parts.topology, container.pack(header, without))
    bent = arrays["m"].copy()
    bent[:, arrays["time_model"] == TIME_SPLINE] = 0.5
    with pytest.raises(ClipFormatError, match="time constant 0"):
        load_clip(parts.topology, container.pack(header, {**arrays, "m": bent}))


def test_rounding_of_spline_knots_stays_within_the_tolerance():
    """With a tolerance, no vertex coordinate at the clip's frames moves by more than it (the steps account
    for the spline's summed weights there)."""
    parts = _spline_parts()
    header, arrays = container.unpack(parts.coefficients)
    data = decode_coefficients(header, arrays, header["n_curves"])
    tol = 1e-4
    rounded = load_clip(parts.topology, encode_coefficients(parts.topology, data, tolerance=tol))
    exact = load_clip(parts.topology, encode_coefficients(parts.topology, data, tolerance=1e-9))
    ft = np.asarray(data.frame_times)
    ts = (ft - ft[0]) / (ft[-1] - ft[0])
    assert np.abs(rounded.evaluate(ts) - exact.evaluate(ts)).max() <= tol * 1.01


def test_time_model_option_and_looping_fits():
    """auto: smooth motion takes the spline; pde: the paper's pairs alone; spline: every moving item; a
    looping fit uses the paper's time model (periodic knots), and the writer refuses spline items with
    constants."""
    poses = synthetic("wave", frames=21)
    curves = simple_curves(poses.vertices[0], max_points=4)
    reports = {m: fit_poses(poses, FitOptions(segments=10, time_model=m), curves=curves).report
               for m in ("auto", "pde", "spline")}
    assert reports["auto"]["time_models"]["spline"] > 0
    assert reports["pde"]["time_models"]["spline"] == 0 and reports["pde"]["time_models"]["pde"] > 0
    counts = reports["spline"]["time_models"]
    assert counts["pde"] == 0 and counts["spline"] >= reports["auto"]["time_models"]["spline"]
    loop = fit_poses(poses, FitOptions(segments=10, loop=True), curves=curves)
    assert loop.report["time_models"]["spline"] == 0
    data = decode_coefficients(*container.unpack(loop.coefficients)[:2], loop.report["curves"])
    assert np.any(data.m != 0)
    data.time_model = np.ones_like(data.time_model)
    with pytest.raises(ValueError, match="time constant 0"):
        encode_coefficients(loop.topology, data)


@pytest.mark.parametrize("kind", ["wave", "travel"])
def test_heldout_frames_beat_catmull_rom_of_the_kept_frames(kind):
    """Fitted from every 4th frame of smooth motion, the frames left out are better than Catmull-Rom of the
    kept frames (the natural spline predicts smooth motion better) and clearly better than straight lines."""
    poses = synthetic(kind)
    curves = simple_curves(poses.vertices[0], max_points=4)
    res = heldout_comparison(poses, 4, FitOptions(target_rel_rms=3e-4, best_effort=True), curves=curves)
    assert res["pde"]["rel_rms"] <= res["catmull_rom"]["rel_rms"], res
    assert res["pde"]["rel_rms"] <= 0.8 * res["linear"]["rel_rms"], res
