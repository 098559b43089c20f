"""Barycentric embedding: exact at rest, affine motions reproduced, outside vertices handled."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.sim.embedding import embed_vertices
from pdeanim.sim.grid import box_tet_mesh

MESH = box_tet_mesh((2.0, 1.0, 1.0), (4, 2, 2), split=5)


@given(seed=st.integers(0, 10_000))
@settings(max_examples=20, deadline=None)
def test_inside_points_get_containing_tets_and_follow_affine_motion(seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform([0, 0, 0], [2, 1, 1], size=(200, 3))
    emb = embed_vertices(MESH, q)
    assert np.all(emb.bary >= -1e-9)
    np.testing.assert_allclose(emb.bary.sum(axis=1), 1.0)
    np.testing.assert_allclose(emb.apply(MESH.points), q, atol=1e-12)
    a = rng.normal(size=(3, 3))
    b = rng.normal(size=3)
    np.testing.assert_allclose(emb.apply(MESH.points @ a.T + b), q @ a.T + b, atol=1e-10)


def test_outside_points_are_exact_at_rest_and_use_a_nearby_tet():
    q = np.array([[2.05, 0.5, 0.5], [-0.02, -0.02, 0.3], [1.0, 1.01, 0.5]])
    emb = embed_vertices(MESH, q)
    np.testing.assert_allclose(emb.apply(MESH.points), q, atol=1e-12)
    assert emb.bary.min() > -0.5  # least extrapolating candidate, not a far tet
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    np.testing.assert_allclose(emb.apply(MESH.points @ rot.T), q @ rot.T, atol=1e-12)


def test_chunking_does_not_change_the_result():
    q = np.random.default_rng(1).uniform([0, 0, 0], [2, 1, 1], size=(300, 3))
    a, b = embed_vertices(MESH, q), embed_vertices(MESH, q, chunk=7)
    np.testing.assert_array_equal(a.tet, b.tet)
    np.testing.assert_allclose(a.bary, b.bary)
