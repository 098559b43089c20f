"""Error-bounded curves: splitting meets the bound, merging keeps it, seams stay together."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.curves import extract_curves
from pdeanim.curves.bounded import bounded_curves, floor_errors, refine_curves, split_curves
from pdeanim.curves.deform import bend_twist
from pdeanim.curves.floor import spatial_floor
from pdeanim.curves.weld import weld_graph
from pdeanim.curveset import CurveSet
from pdeanim.errors import ParameterError
from pdeanim.poses import make_poses


@pytest.fixture(scope="module")
def bent_spot(spot):
    v, f = spot
    return bend_twist(v, 10), f


def test_tight_target_splits_until_every_curve_meets_it(bent_spot):
    frames, f = bent_spot
    start = extract_curves(frames[0], f, target_points=16)
    loose = spatial_floor(frames, start, "displacement")
    target = loose.rel_rms  # the start is far above half of this on many curves
    curves, rep = refine_curves(frames, start, target, motion="displacement")
    curves.validate(frames.shape[1])
    assert rep["met"] and rep["splits"] > 0 and curves.n_curves > start.n_curves
    per = floor_errors(frames.astype(np.float64), "displacement")(curves, np.arange(curves.n_curves))
    assert per.max() <= 0.5 * target + 1e-15
    assert spatial_floor(frames, curves, "displacement").rel_rms < loose.rel_rms


def test_loose_target_merges_short_neighbours(bent_spot):
    frames, f = bent_spot
    start = extract_curves(frames[0], f, target_points=3)
    curves, rep = refine_curves(make_poses(frames, f), start, 0.05, motion="rigid")
    curves.validate(frames.shape[1])
    assert rep["merges"] > 0 and curves.n_curves < start.n_curves and rep["met"]
    assert rep["mean_points"] > 3


def test_custom_error_function_and_seams_kept_together(messy):
    v, f = messy
    frames = np.stack([v, v * 1.1, v * np.array([1.0, 1.2, 1.0])])
    start = extract_curves(v, f, target_points=8)
    calls = []

    def err(cs: CurveSet) -> np.ndarray:  # every curve with more than 3 distinct positions is "bad"
        cs.validate(len(v))  # always called with the whole partition
        calls.append(cs.n_curves)
        return np.array([len(np.unique(v[cs.order[a:b]], axis=0)) > 3 for a, b in
                         zip(cs.offsets[:-1], cs.offsets[1:], strict=True)], float)

    curves, rep = refine_curves(frames, start, 0.5, per_curve_error=err)
    curves.validate(len(v))
    assert rep["met"] and len(calls) >= 2
    g = weld_graph(v, f)
    cid, _ = curves.curve_of_vertex(len(v))
    for w in np.flatnonzero(np.bincount(g.weld) > 1):
        assert len(set(cid[g.weld == w])) == 1


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 40))
def test_refine_keeps_a_partition(seed, n):
    rng = np.random.default_rng(seed)
    rest = rng.integers(0, 4, size=(n, 3)).astype(float)
    frames = np.stack([rest, rest + rng.normal(0, 0.3, rest.shape), rest * 1.3])
    start = extract_curves(rest, rng.integers(0, n, size=(n, 3)), target_points=int(rng.integers(1, 9)))
    curves, rep = refine_curves(frames, start, float(rng.choice([1e-3, 1e-2, 1.0])), motion="rigid")
    curves.validate(n)
    assert rep["curves"] == curves.n_curves


def test_split_halves_distinct_points():
    rest = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0], [3, 0, 0], [9, 9, 9]])
    cs = CurveSet.from_lists([[0, 1, 2, 3, 4, 5], [6]])
    out = split_curves(rest, cs, np.array([True, True]))
    assert [list(out.order[a:b]) for a, b in zip(out.offsets[:-1], out.offsets[1:], strict=True)] == [
        [0, 1, 2], [3, 4, 5], [6]]


def test_bounded_curves_end_to_end_and_bad_args(bent_spot):
    frames, f = bent_spot
    curves, rep = bounded_curves(frames, f, 3e-3, motion="rigid")
    curves.validate(frames.shape[1])
    assert rep["met"] and rep["rel_rms"] <= 1.5e-3
    with pytest.raises(ParameterError):
        refine_curves(frames, curves, -1.0)
    with pytest.raises(ParameterError):
        refine_curves(frames, curves, 1e-3, motion="wobbly")


@pytest.mark.slow
def test_refine_with_model_fit_errors(morph):
    from pdeanim.fit.pipeline import fit_errors

    x, f = morph
    poses = make_poses(x[::18], f)  # 12 frames keep the fits quick
    start = extract_curves(poses.vertices[0], f, target_points=10)
    errors = fit_errors(poses)
    before = errors(start)
    target = float(np.median(before))
    curves, rep = refine_curves(poses, start, target, per_curve_error=errors, max_rounds=3)
    curves.validate(poses.n_vertices)
    assert rep["splits"] > 0 and curves.n_curves > start.n_curves
    assert rep["worst_curve_rel_rms"] < before.max()
