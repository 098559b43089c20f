"""Integer codes of the dynamic-PDE clip format (docs/format.md §3.2-3.3): the stored clip is the fitted
model within the stated quantisation bound, integer round trips are exact, broken parts raise clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.errors import ClipFormatError
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model import knotbasis, quantise
from pdeanim.model.clipformat import (
    decode_coefficients,
    decode_topology,
    encode_coefficients,
    encode_topology,
)


@given(st.lists(st.integers(-(2**29), 2**29), min_size=0, max_size=50))  # differences fit int32
def test_zigzag_differences_round_trip(values):
    q = np.asarray(values, np.int64)
    z = quantise.zigzag_deltas(q)
    assert z.dtype == np.uint32
    np.testing.assert_array_equal(quantise.undo_zigzag_deltas(z), q)


@given(st.integers(1, 6), st.integers(1, 4), st.booleans(), st.integers(0, 1000))
def test_knot_tracks_round_trip_with_either_difference_order(S1, C, smooth, seed):
    rng = np.random.default_rng(seed)
    if smooth:  # knots on a line in time: second differences are zero
        codes = (np.arange(S1)[:, None, None, None] * rng.integers(-50, 50, (1, C, 3, 4))
                 + rng.integers(-(2**20), 2**20, (1, C, 3, 4)))
    else:
        codes = rng.integers(-(2**27), 2**27, (S1, C, 3, 4))
    tracks, order = quantise.encode_knot_tracks(codes)
    assert tracks.shape == (C, 3, 4, S1) and tracks.dtype == np.uint32 and order in (1, 2)
    np.testing.assert_array_equal(quantise.decode_knot_tracks(tracks, order), codes)
    other = 3 - order
    again = quantise.zigzag_deltas(np.moveaxis(codes, 0, -1) if other == 1 else
                                   np.diff(np.moveaxis(codes, 0, -1), axis=-1, prepend=0), axis=-1)
    np.testing.assert_array_equal(quantise.decode_knot_tracks(again, other), codes)


@pytest.fixture(scope="module")
def max_fit(morph_small, short_curves):
    """A fit with a max target: every rounding is bounded per coordinate."""
    return fit_poses(morph_small, FitOptions(target_rel_max=3e-2), curves=short_curves)


def _float_bytes(parts) -> int:
    """Bytes of the same clip as raw float32 arrays (rest, u, faces, curves, knots, constants), no codes."""
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    topo = decode_topology(th, ta)
    coef = decode_coefficients(ch, ca, topo.curves.n_curves)
    raw = {"rest": topo.rest, "u": topo.u[:, :1].astype(np.float32), "faces": topo.faces,
           "order": topo.curves.order, "offsets": topo.curves.offsets, "knots": coef.knots,
           "m": coef.m.astype(np.float32), "D": coef.D, "segment_t": coef.segment_t}
    return len(container.pack({}, raw))


def test_the_stored_clip_is_the_fit_within_the_bound_and_small(max_fit):
    r = max_fit.report
    tol = r["quantisation_tolerance"]
    assert tol == pytest.approx(0.1 * 3e-2 * r["diagonal"])
    assert r["quantisation_knot_rms"] is None
    # per vertex, the stored clip's distance differs from the unrounded fit's by at most the rounding: rest
    # and knots each round by at most tol per coordinate
    assert r["float32_vs_float64_max"] <= 2 * np.sqrt(3) * tol
    assert r["target_met"] and r["rel_max"] <= 3e-2
    assert len(max_fit.topology) + len(max_fit.coefficients) < 0.5 * _float_bytes(max_fit)


def test_an_rms_target_lets_the_knots_use_what_the_fit_leaves(morph_small, short_curves):
    """With only an RMS target, the knots' rounding adds at most its budget to the RMS; the target holds."""
    parts = fit_poses(morph_small, FitOptions(target_rel_rms=3e-3), curves=short_curves)
    r = parts.report
    assert r["target_met"] and r["rel_rms"] <= 3e-3
    added = np.sqrt(max(r["rms"] ** 2 - r["unrounded_rms"] ** 2, 0.0))
    assert 0 < r["quantisation_knot_rms"]
    assert added <= r["quantisation_knot_rms"] + r["quantisation_tolerance"]
    assert len(parts.topology) + len(parts.coefficients) < 0.4 * _float_bytes(parts)


def test_arrays_are_exact_integer_codes(max_fit):
    parts = max_fit
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    topo = decode_topology(th, ta)
    coef = decode_coefficients(ch, ca, topo.curves.n_curves)
    steps = ca["knot_step"].astype(np.float64)
    assert np.all(np.log2(steps) == np.round(np.log2(steps)))  # powers of two
    plain = coef.knots
    if ch["knot_rank"]:  # the knots less their shared-basis part are the residual codes times the steps
        weights = quantise.unzigzag(ca["knot_weights"])
        plain = coef.knots - knotbasis.basis_part(weights, steps, ca["knot_basis"]).astype(np.float32)
    codes = np.rint(plain / steps[None, :, :, None])
    np.testing.assert_array_equal(quantise.dequantise(codes, steps[None, :, :, None]),
                                  quantise.dequantise(quantise.decode_knot_tracks(ca["knots"],
                                                                                  ch["knot_differences"]),
                                                      steps[None, :, :, None]))
    # re-encoding the decoded clip gives the same bytes: the codes are a fixed point
    again = encode_topology(topo.curves, topo.u, topo.faces, topo.rest, topo.param_mode,
                            tolerance=parts.report["quantisation_tolerance"])
    assert again == parts.topology


@settings(max_examples=30, deadline=None)
@given(scale=st.floats(1e-4, 1e4), tol_share=st.floats(1e-6, 1e-2), seed=st.integers(0, 1000))
def test_rest_and_knot_rounding_stay_within_the_tolerance(scale, tol_share, seed):
    """Whatever the scale: decoded rest within tol per coordinate; the knots' share of any vertex within
    tol (the bound the knot steps are chosen for)."""
    rng = np.random.default_rng(seed)
    from pdeanim.curveset import CurveSet
    from pdeanim.model.clipformat import CoefficientData
    from pdeanim.model.families import space_basis

    V, S = 12, 3
    rest = (rng.normal(size=(V, 3)) * scale).astype(np.float32)
    curves = CurveSet(rng.permutation(V).astype(np.int32), np.array([0, 4, 9, 12], np.int32))
    u = np.zeros((V, 3), np.float32)
    for c in range(3):
        idx = curves.order[curves.offsets[c]:curves.offsets[c + 1]]
        u[idx] = np.linspace(0, 1, len(idx))[:, None]
    tol = tol_share * scale
    topo_b = encode_topology(curves, u, np.zeros((0, 3), np.int32), rest, "chord", tolerance=tol)
    topo = decode_topology(*container.unpack(topo_b))
    assert np.abs(topo.rest.astype(np.float64) - rest).max() <= tol * (1 + 1e-6) + 1e-7 * scale
    family = rng.integers(0, 4, size=(S, 3, 3)).astype(np.uint8)
    family = (family // 2) * 2 + family[:1] % 2  # one space kind per item
    data = CoefficientData(np.linspace(0, 1, S + 1), np.arange(5.0), family,
                           rng.uniform(0, 2.5, size=(S, 3, 3)).astype(np.float32),
                           rng.uniform(0, 20, size=(3, 3)).astype(np.float32),
                           (rng.normal(size=(S + 1, 3, 3, 4)) * scale).astype(np.float32),
                           "displacement", False, {})
    coef = decode_coefficients(*container.unpack(encode_coefficients(topo_b, data, tolerance=tol)), 3)
    cid, _ = topo.curves.curve_of_vertex(V)
    err = np.abs(coef.knots.astype(np.float64) - data.knots)  # (S+1, C, 3, 4)
    kinds = ("D0", "D1")
    for w in range(3):
        for v in range(V):
            c = cid[v]
            B = np.abs(space_basis(np.array([float(topo.u[v, w])]), float(data.D[c, w]),
                                   kinds[family[0, c, w] % 2])[0])
            pair = 1.0 / np.cos(np.where(family[:, c, w] >= 2, data.m[:, c, w], 0.0).max() / 2)
            assert (err[:, c, w] @ B).max() * pair <= tol * (1 + 1e-5) + 1e-6 * scale


def _edit(blob: bytes, header: dict | None = None, **arrays) -> bytes:
    h, a = container.unpack(blob)
    return container.pack({**h, **(header or {})}, {**a, **arrays})


def test_broken_parts_raise_clear_errors(max_fit):
    parts = max_fit
    topo, coef = parts.topology, parts.coefficients
    h, a = container.unpack(topo)
    swapped = quantise.undo_zigzag_deltas(a["order"]).copy()
    swapped[0] = swapped[1]
    cases = [
        (_edit(topo, order=quantise.zigzag_deltas(swapped)), "curves are invalid"),
        (_edit(topo, {"rest_step": -1.0}), "steps must be positive"),
        (_edit(topo, {"u_step": None}), "u_step"),
        (_edit(topo, curve_lengths=a["curve_lengths"][:-1]), "curves are invalid"),
        (_edit(topo, faces=quantise.zigzag_deltas(np.full(3 * len(a["faces"]), 10**6)).reshape(-1, 3)),
         "faces index outside"),
        (_edit(topo, {"u_step": 2.0**40}), "u must lie in"),
        (_edit(topo, {"n_vertices": "x"}), "non-negative integer"),
    ]
    for blob, match in cases:
        with pytest.raises(ClipFormatError, match=match):
            decode_topology(*container.unpack(blob))
    ch, ca = container.unpack(coef)
    C = len(ca["knot_step"])
    # a clip with a knot at every frame leaves segment_t out: the readers check its dtype when it is written
    ca.setdefault("segment_t", decode_coefficients(ch, ca, C).segment_t)
    for name, dtype in (("segment_t", np.float32), ("frame_times", np.float32), ("D", np.float64)):
        with pytest.raises(ClipFormatError, match=f"'{name}' has dtype"):
            decode_coefficients(*container.unpack(_edit(coef, **{name: ca[name].astype(dtype)})), C)
    with pytest.raises(ClipFormatError, match="knot steps must be positive"):
        decode_coefficients(*container.unpack(_edit(coef, knot_step=np.zeros_like(ca["knot_step"]))), C)
    with pytest.raises(ClipFormatError, match="no 'knot_step'"):
        h2, a2 = container.unpack(coef)
        decode_coefficients(h2, {k: v for k, v in a2.items() if k != "knot_step"}, C)
