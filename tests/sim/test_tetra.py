"""fTetWild tetrahedralization: target tet count, orientation, cache, isolation and failures."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pdeanim.errors import ParameterError, TetrahedralizationError
from pdeanim.mesh.io import SurfaceMesh, load_mesh
from pdeanim.sim.tetra import TetParams, enclosed_volume, tetrahedralize


@pytest.fixture(scope="module")
def spot_tets(spot_path, tmp_path_factory):
    cache = tmp_path_factory.mktemp("tetcache")
    spot = load_mesh(spot_path)
    return spot, cache, tetrahedralize(spot, TetParams(target_tets=800), cache_dir=cache)


def test_spot_tets_fill_the_surface(spot_tets):
    spot, _, tets = spot_tets
    vol = tets.volumes()
    assert np.all(vol > 0)
    assert 0.6 * 800 <= tets.n_tets <= 1.6 * 800
    assert vol.sum() == pytest.approx(enclosed_volume(spot.vertices, spot.faces), rel=0.08)
    lo, hi = spot.bbox()
    assert np.all(tets.points >= lo - 0.05) and np.all(tets.points <= hi + 0.05)


def test_cache_returns_the_same_tets_and_cwd_stays_clean(spot_tets, tmp_path, monkeypatch):
    spot, cache, tets = spot_tets
    monkeypatch.chdir(tmp_path)
    again = tetrahedralize(spot, TetParams(target_tets=800), cache_dir=cache)
    np.testing.assert_array_equal(again.tets, tets.tets)
    np.testing.assert_array_equal(again.points, tets.points)
    assert len(list(cache.glob("tets-*.npz"))) == 1
    assert os.listdir(tmp_path) == []


def test_flat_and_degenerate_surfaces_fail_cleanly(tmp_path):
    flat = SurfaceMesh(
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]), np.array([[0, 1, 2], [1, 3, 2]])
    )
    with pytest.raises(TetrahedralizationError, match="flat"):
        tetrahedralize(flat, TetParams(target_tets=100), workdir=tmp_path)
    # a single sliver triangle pair with thickness: fTetWild crashes in its child process, we raise
    sliver = SurfaceMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1e-3]]), np.array([[0, 1, 2]]))
    with pytest.raises(TetrahedralizationError):
        tetrahedralize(sliver, TetParams(target_tets=100), workdir=tmp_path)


def test_params_are_checked():
    with pytest.raises(ParameterError):
        TetParams(target_tets=5)


def test_large_surfaces_are_decimated_before_fTetWild(tmp_path):
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0)).subdivide_to_size(0.03)
    mesh = SurfaceMesh(np.asarray(box.vertices), np.asarray(box.faces))
    assert len(mesh.faces) > 20_000
    tets = tetrahedralize(mesh, TetParams(target_tets=400, max_surface_faces=1500), workdir=tmp_path)
    assert tets.volumes().sum() == pytest.approx(2.0, rel=0.05)
    assert 0.4 * 400 <= tets.n_tets <= 2.0 * 400


def test_cache_key_names_the_decimation_method_only_when_it_applies(spot_path, monkeypatch):
    """Quadric decimation and vertex clustering give different surfaces, hence different tets: a surface over
    its budget (2 faces per target tet) gets a key that changes with the method (injected here); a surface
    within the budget is never decimated and keeps its key."""
    import pdeanim.sim.tetra as tetra

    spot = load_mesh(spot_path)
    small, large = TetParams(target_tets=3000), TetParams(target_tets=800)
    assert tetra.surface_budget(800, large.max_surface_faces) < len(spot.faces)
    assert tetra.surface_budget(3000, small.max_surface_faces) >= len(spot.faces)
    keys = {}
    for method in ("vertex-clustering", "quadric fast-simplification 0.1"):
        monkeypatch.setattr(tetra, "decimation_method", lambda method=method: method)
        keys[method] = (tetra.cache_key(spot, small), tetra.cache_key(spot, large))
    (small_a, large_a), (small_b, large_b) = keys.values()
    assert small_a == small_b and large_a != large_b
