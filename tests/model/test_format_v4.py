"""Format version 4: Catmull-Rom time tangents (docs/format.md §3.10), their fit and their evaluation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.errors import ClipFormatError
from pdeanim.model import clipmodel, tangents
from pdeanim.model.clipformat import decode_coefficients, encode_coefficients
from pdeanim.model.fitclip import FitOptions, fit_poses
from pdeanim.model.heldout import heldout_comparison
from pdeanim.model.segments import Segmentation
from pdeanim.model.simplecurves import simple_curves
from pdeanim.model.tangents import hermite_weights, predict_cubic, prefer_tangents, solve_cubic_knots
from tests.conformance.generate import _synthetic_dynamic
from tests.model.test_fast_paths import _plain_frame
from tests.model.test_inbetween import synthetic


def _dense_design(segm: Segmentation) -> np.ndarray:
    """(F, S + 1) design of the cubic model from the weights, for a plain least-squares reference."""
    idx, w = hermite_weights(segm.segment_t, segm.frame_segment(), segm.frame_tau())
    A = np.zeros((len(segm.t), segm.n_segments + 1))
    for j in range(4):
        np.add.at(A, (np.arange(len(segm.t)), idx[:, j]), w[:, j])
    return A


@settings(max_examples=40, deadline=None)
@given(st.integers(4, 40), st.data())
def test_banded_cubic_solve_equals_dense_least_squares(n_frames, data):
    """The QR sweep over four-knot bands gives the least-squares knots of the dense design (any segmentation,
    uneven frame times)."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    t = np.concatenate([[0.0], np.sort(rng.uniform(0, 1, n_frames - 2)), [1.0]])
    inner = data.draw(st.lists(st.integers(1, n_frames - 2), max_size=n_frames - 2, unique=True))
    segm = Segmentation(np.array(sorted([0, n_frames - 1, *inner]), np.int64), t)
    b = rng.normal(size=(3, n_frames, 4))
    z = solve_cubic_knots(b, segm)
    A = _dense_design(segm)
    ref = np.linalg.lstsq(A, np.moveaxis(b, 1, 0).reshape(n_frames, -1), rcond=None)[0]
    scale = 1 + np.abs(ref).max()
    np.testing.assert_allclose(z, np.moveaxis(ref.reshape(-1, 3, 4), 1, 0), atol=1e-8 * scale)
    np.testing.assert_allclose(predict_cubic(z, segm), np.moveaxis((A @ ref).reshape(n_frames, 3, 4), 1, 0),
                               atol=1e-9 * (1 + np.abs(ref).max()))


def test_cubic_interpolates_knots_and_reproduces_straight_lines():
    """Weights sum to 1, the cubic passes through its knots, and knots on a line give that line."""
    segment_t = np.array([0.0, 0.1, 0.45, 0.5, 1.0])
    seg = np.repeat(np.arange(4), 50)
    tau = np.tile(np.linspace(0, 1, 50), 4)
    idx, w = hermite_weights(segment_t, seg, tau)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-14)
    on_line = 3.0 - 2.0 * segment_t
    t = segment_t[seg] + tau * (segment_t[seg + 1] - segment_t[seg])
    np.testing.assert_allclose((w * on_line[idx]).sum(1), 3.0 - 2.0 * t, atol=1e-13)
    ends = np.isin(tau, [0.0])
    np.testing.assert_allclose((w * on_line[idx]).sum(1)[ends], on_line[seg[ends]], atol=1e-15)


def test_tangent_choice_prefers_the_cubic_unless_lines_are_clearly_better(monkeypatch):
    """Smooth motion and white noise (the cubic's error between every other frame 1.1x the lines' there) are
    candidates, static items are not; with a stricter gain, noise keeps lines and smooth motion the cubic."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 1, 40)
    smooth = np.sin(2 * np.pi * 1.5 * t)[None, :, None] * np.ones((1, 1, 4))
    noise = rng.normal(size=(1, 40, 4))
    static = np.zeros((1, 40, 4))
    b = np.concatenate([smooth, noise, static])
    assert prefer_tangents(b, t).tolist() == [True, True, False]
    monkeypatch.setattr(tangents, "CUBIC_GAIN", 0.9)
    assert prefer_tangents(b, t).tolist() == [True, False, False]
    assert not prefer_tangents(b[:, :3], t[:3]).any()  # too few frames to tell


def _v4_parts():
    return _synthetic_dynamic("displacement", "chord", False, version=4)()


def test_version_4_round_trip_and_the_plain_definition():
    """Encoded tangents decode unchanged; the compiled, numpy and definition evaluations agree."""
    parts = _v4_parts()
    header, arrays = container.unpack(parts.coefficients)
    assert header["format_version"] == 4 and header["knot_rank"] == 0
    data = decode_coefficients(header, arrays, header["n_curves"])
    np.testing.assert_array_equal(data.tangents, arrays["tangents"])
    assert 0 < data.tangents.sum() < data.tangents.size
    clip = load_clip(parts.topology, parts.coefficients)
    ts = np.linspace(-0.1, 1.1, 61)
    fast = clip.evaluate(ts)
    assert np.any(clip._cubic_items[0]) and fast.dtype == np.float32
    # the plain definition in float64 (tests.model.test_fast_paths uses it on a fitted clip)
    scale = np.abs(fast).max()
    for k, t in enumerate(ts):
        np.testing.assert_allclose(fast[k], _plain_frame(clip, float(t)), atol=2e-6 * scale, rtol=0)


def test_numpy_fallback_equals_compiled_cubic_path(monkeypatch):
    parts = _v4_parts()
    clip = load_clip(parts.topology, parts.coefficients)
    ts = np.linspace(0, 1, 23)
    compiled = clip.evaluate(ts)
    monkeypatch.setattr(clipmodel, "COMPILED", False)
    plain = load_clip(parts.topology, parts.coefficients)
    np.testing.assert_array_equal(plain.evaluate(ts), compiled)


def _with(parts, change) -> bytes:
    header, arrays = container.unpack(parts.coefficients)
    change(header, arrays)
    return container.pack(header, arrays)


@pytest.mark.parametrize("change, message", [
    (lambda h, a: a.pop("tangents"), "tangents"),
    (lambda h, a: a.__setitem__("tangents", a["tangents"][:, :2].copy()), "shape"),
    (lambda h, a: a.__setitem__("tangents", a["tangents"].astype(np.uint16)), "dtype"),
    (lambda h, a: a.__setitem__("tangents", a["tangents"] * 2), "0 or 1"),
    (lambda h, a: h.__setitem__("knot_rank", -1), "knot_rank"),
    (lambda h, a: h.__setitem__("knot_rank", 99), "knot_rank"),
    (lambda h, a: a.__setitem__("knot_basis", np.zeros((1, 5), np.float32)), "knot_basis"),
])
def test_version_4_readers_reject_what_the_spec_rejects(change, message):
    parts = _v4_parts()
    bad = _with(parts, change)
    with pytest.raises(ClipFormatError, match=message):
        load_clip(parts.topology, bad)


def test_rounding_of_cubic_knots_stays_within_the_tolerance():
    """With a tolerance, no vertex coordinate of the decoded clip moves by more than it (the cubic's summed
    weights reach 1.5, which the steps account for)."""
    parts = _v4_parts()
    header, arrays = container.unpack(parts.coefficients)
    data = decode_coefficients(header, arrays, header["n_curves"])
    tol = 1e-4
    coarse = encode_coefficients(parts.topology, data, 4, tolerance=tol)
    exact = load_clip(parts.topology, encode_coefficients(parts.topology, data, 4, tolerance=1e-9))
    rounded = load_clip(parts.topology, coarse)
    ts = np.linspace(0, 1, 101)
    assert np.abs(rounded.evaluate(ts) - exact.evaluate(ts)).max() <= tol * 1.01


def test_version_3_or_a_looping_fit_writes_no_tangents():
    poses = synthetic("wave", frames=21)
    curves = simple_curves(poses.vertices[0], max_points=4)
    v4 = fit_poses(poses, FitOptions(segments=10, format_version=4), curves=curves)
    v3 = fit_poses(poses, FitOptions(segments=10, format_version=3), curves=curves)
    loop = fit_poses(poses, FitOptions(segments=10, loop=True), curves=curves)
    assert container.unpack(v4.coefficients)[0]["format_version"] == 4 and v4.report["tangent_items"] > 0
    for parts in (v3, loop):
        assert container.unpack(parts.coefficients)[0]["format_version"] in (2, 3)
        assert parts.report["tangent_items"] == 0
    with pytest.raises(ValueError, match="version 4"):
        data = decode_coefficients(*container.unpack(v4.coefficients)[:2], v4.report["curves"])
        encode_coefficients(v4.topology, data, 3)


@pytest.mark.parametrize("kind", ["wave", "travel"])
def test_heldout_frames_follow_catmull_rom_of_the_kept_frames(kind):
    """Fitted from every 4th frame of smooth motion, the frames left out are about as good as Catmull-Rom of
    the kept frames and clearly better than straight lines (version 3: equal to the lines)."""
    poses = synthetic(kind)
    curves = simple_curves(poses.vertices[0], max_points=4)
    res = heldout_comparison(poses, 4, FitOptions(target_rel_rms=3e-4, best_effort=True, format_version=4),
                             curves=curves)
    assert res["pde"]["rel_rms"] <= 1.1 * res["catmull_rom"]["rel_rms"], res
    assert res["pde"]["rel_rms"] <= 0.8 * res["linear"]["rel_rms"], res
