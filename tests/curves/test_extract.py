"""Curve extraction: partition, determinism, smoothness and awkward inputs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.curves import extract_curves
from pdeanim.curves.quality import quality_summary, turning_angles
from pdeanim.curves.weld import weld_graph
from pdeanim.errors import MeshInputError, ParameterError


def assert_partition(curves, n):
    curves.validate(n)
    assert curves.order.dtype == np.int32 and curves.offsets.dtype == np.int32


@pytest.mark.parametrize("name", ["spot", "bob", "morph"])
def test_partition_on_real_meshes(name, request):
    v, f = request.getfixturevalue(name)
    v = v[0] if v.ndim == 3 else v
    cs = extract_curves(v, f)
    assert_partition(cs, len(v))
    assert cs.n_curves > 10


def test_messy_mesh_partition_and_copies_adjacent(messy):
    v, f = messy
    cs = extract_curves(v, f, target_points=6)
    assert_partition(cs, len(v))
    g = weld_graph(v, f)
    # copies of a welded point sit next to each other on the same curve
    cid, pos = cs.curve_of_vertex(len(v))
    for w in np.flatnonzero(np.bincount(g.weld) > 1):
        members = np.flatnonzero(g.weld == w)
        assert len(set(cid[members])) == 1
        assert np.ptp(pos[members]) == len(members) - 1
    # the isolated far point shares its curve only with the other isolated points
    far = len(v) - 1
    same = cs.order[cs.offsets[cid[far]]:cs.offsets[cid[far] + 1]]
    assert set(same.tolist()) <= set(range(len(v) - 3, len(v)))


@pytest.mark.parametrize("field", ["axis", "fiedler", "geodesic"])
@pytest.mark.parametrize("method", ["meridians", "rings"])
def test_every_field_and_method_partitions(messy, field, method):
    v, f = messy
    assert_partition(extract_curves(v, f, field=field, method=method), len(v))


def test_no_faces_and_empty():
    v = np.random.default_rng(1).standard_normal((37, 3))
    cs = extract_curves(v, None, target_points=5)
    assert_partition(cs, 37)
    assert cs.lengths.max() <= 8
    empty = extract_curves(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    assert empty.n_curves == 0 and len(empty.order) == 0
    one = extract_curves(np.zeros((1, 3)), None)
    assert one.n_curves == 1
    same = extract_curves(np.ones((5, 3)), np.array([[0, 1, 2], [2, 3, 4]]))
    assert same.n_curves == 1 and same.order.tolist() == [0, 1, 2, 3, 4]


def test_deterministic(spot):
    v, f = spot
    a = extract_curves(v, f, seed=3)
    b = extract_curves(v.copy(), f.copy(), seed=3)
    assert np.array_equal(a.order, b.order) and np.array_equal(a.offsets, b.offsets)


def test_curves_are_smooth_and_follow_edges(bob):
    v, f = bob
    cs = extract_curves(v, f)
    q = quality_summary(v, f, cs)
    assert q["turn_median_deg"] < 15 and q["turn_p90_deg"] < 45
    assert 7 <= q["mean_points"] <= 13
    # consecutive points on a curve are joined by a mesh edge
    g = weld_graph(v, f)
    adj = g.adjacency()
    w = g.weld[cs.order]
    cid = np.repeat(np.arange(cs.n_curves), cs.lengths)
    a, b = w[:-1], w[1:]
    step = (cid[:-1] == cid[1:]) & (a != b)
    assert np.all(np.asarray(adj[a[step], b[step]]).ravel() == 1)


def test_target_points_controls_length(spot):
    v, f = spot
    short = extract_curves(v, f, target_points=5)
    long = extract_curves(v, f, target_points=20)
    assert short.n_curves > 2 * long.n_curves
    assert len(turning_angles(v, short)) > 0


def test_bad_input_raises():
    v = np.zeros((4, 3))
    with pytest.raises(ParameterError):
        extract_curves(v, None, field="nope")
    with pytest.raises(ParameterError):
        extract_curves(v, None, target_points=0)
    with pytest.raises(ParameterError):
        extract_curves(v, None, method="zigzag")
    with pytest.raises(MeshInputError):
        extract_curves(np.zeros((4, 2)), None)
    with pytest.raises(MeshInputError):
        extract_curves(v, np.array([[0, 1, 9]]))
    with pytest.raises(MeshInputError):
        extract_curves(np.full((4, 3), np.nan), None)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 10_000), n_faces=st.integers(0, 60),
       dup=st.integers(0, 5), target=st.integers(1, 12))
def test_random_small_meshes_partition(n, seed, n_faces, dup, target):
    rng = np.random.default_rng(seed)
    v = rng.integers(-3, 4, size=(n, 3)).astype(float)  # integer grid: many coincident points
    if dup:
        v = np.concatenate([v, v[rng.integers(0, n, dup)]])
    f = rng.integers(0, len(v), size=(n_faces, 3))
    cs = extract_curves(v, f, target_points=target, field=["axis", "fiedler", "geodesic"][seed % 3])
    assert_partition(cs, len(v))
