"""Structured box meshes, tet cleaning, colouring and the decimation fallback."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.errors import ParameterError, TetrahedralizationError
from pdeanim.sim.coloring import color_tets
from pdeanim.sim.decimate import decimate
from pdeanim.sim.grid import box_tet_mesh
from pdeanim.sim.tetmesh import clean_tet_mesh, tet_volumes


@given(nx=st.integers(1, 4), ny=st.integers(1, 3), nz=st.integers(1, 3), split=st.sampled_from([5, 6]))
@settings(max_examples=25, deadline=None)
def test_box_is_positive_conforming_and_fills_the_volume(nx, ny, nz, split):
    mesh = box_tet_mesh((2.0, 1.0, 0.5), (nx, ny, nz), split=split)
    vol = mesh.volumes()
    assert np.all(vol > 0)
    assert vol.sum() == pytest.approx(1.0)
    assert mesh.n_tets == split * nx * ny * nz
    # conforming: the boundary is exactly the box's 2 triangles per outer cell face
    assert len(mesh.surface_faces()) == 4 * (nx * ny + ny * nz + nx * nz)


def test_box_rejects_bad_cells():
    with pytest.raises(ParameterError):
        box_tet_mesh((1, 1, 1), (0, 1, 1))
    with pytest.raises(ParameterError):
        box_tet_mesh((1, 1, 1), (1, 1, 1), split=4)


def test_clean_flips_negative_tets_and_drops_degenerate_ones():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 2, 2], [1, 1, 0], [9, 9, 9]], float)
    tets = np.array([[0, 2, 1, 3], [0, 1, 2, 3], [0, 1, 5, 2]])  # negative, positive, flat (coplanar)
    mesh = clean_tet_mesh(points, tets)
    assert mesh.n_tets == 2 and np.all(mesh.volumes() > 0)
    assert mesh.n_points == 4  # unused points (and the flat tet's extra point) are dropped
    with pytest.raises(TetrahedralizationError):
        clean_tet_mesh(points, np.zeros((0, 4), int))
    with pytest.raises(TetrahedralizationError):
        clean_tet_mesh(points, np.array([[0, 1, 5, 2]]))


@given(n=st.integers(1, 4), split=st.sampled_from([5, 6]))
@settings(max_examples=10, deadline=None)
def test_colouring_is_a_partition_of_independent_sets(n, split):
    mesh = box_tet_mesh((1, 1, 1), (n, n, 2), split=split)
    colors = color_tets(mesh.tets, mesh.n_points)
    everything = np.sort(np.concatenate(colors))
    np.testing.assert_array_equal(everything, np.arange(mesh.n_tets))
    for c in colors:
        used = mesh.tets[c].ravel()
        assert len(np.unique(used)) == len(used)  # no point twice within a colour
    again = color_tets(mesh.tets, mesh.n_points)  # deterministic
    assert len(again) == len(colors) and all(np.array_equal(a, b) for a, b in zip(colors, again, strict=True))


def test_decimation_reduces_faces_and_keeps_the_shape(spot_path):
    from pdeanim.mesh.io import load_mesh

    spot = load_mesh(spot_path)
    v, f = decimate(spot.vertices, spot.faces, 1500)
    assert 300 < len(f) <= 1500 and f.max() < len(v)
    np.testing.assert_allclose(v.min(axis=0), spot.vertices.min(axis=0), atol=0.1)
    np.testing.assert_allclose(v.max(axis=0), spot.vertices.max(axis=0), atol=0.1)
    same_v, same_f = decimate(spot.vertices, spot.faces, 10_000)
    assert same_f is spot.faces


def test_tet_volumes_sign():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    assert tet_volumes(p, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(1 / 6)
    assert tet_volumes(p, np.array([[0, 2, 1, 3]]))[0] == pytest.approx(-1 / 6)
