"""End to end: simulate_mesh on spot.obj and bob.obj, and the ``pdeanim simulate`` command."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.cli import main
from pdeanim.errors import ParameterError
from pdeanim.mesh.io import load_mesh
from pdeanim.poses import load_poses_npz
from pdeanim.sim.simulate import SceneParams, simulate_mesh


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("tets")


def test_spot_pinned_and_driven(spot_path, cache):
    spot = load_mesh(spot_path)
    scene = SceneParams(frames=9, fps=15, target_tets=600, young=5e4,
                        pins=[{"box": [0, 0, 0, 1, 1, 0.3], "relative": True}],
                        drivers=[{"region": {"box": [0, 0, 0.8, 1, 1, 1], "relative": True},
                                  "keyframes": [{"t": 1.0, "rotate": [0, 0, 1, 60]}]}])
    stages = []
    poses = simulate_mesh(spot, scene, progress=lambda f, s: stages.append((f, s)), cache_dir=cache)
    assert poses.vertices.shape == (9, 2930, 3) and poses.vertices.dtype == np.float32
    np.testing.assert_array_equal(poses.faces, spot.faces)
    np.testing.assert_allclose(poses.vertices[0], spot.vertices, atol=1e-6)  # exact rest pose
    assert stages[0] == (0.0, "tetrahedralize") and stages[-1] == (1.0, "simulate 8/8")
    assert all(a[0] <= b[0] for a, b in zip(stages, stages[1:], strict=False))
    moved = np.linalg.norm(poses.vertices - poses.vertices[0], axis=2).max(axis=1)
    assert moved[1] < moved[4] < moved[-1] and 0.1 < moved[-1] < spot.diagonal()
    tail = spot.vertices[:, 2] < spot.vertices[:, 2].min() + 0.05 * np.ptp(spot.vertices[:, 2])
    assert np.abs(poses.vertices[:, tail] - spot.vertices[tail]).max() < 1e-6  # pinned end stays
    meta = poses.meta
    assert meta["tets"] > 300 and meta["substeps"] >= 1 and meta["versions"]["pytetwild"] == "0.2.3"
    assert SceneParams.from_dict(meta["scene"]) == scene


def test_cli_bob_twist_writes_moving_poses(bob_path, tmp_path, cache, capsys):
    out = tmp_path / "bob.npz"
    code = main(["simulate", str(bob_path), "--frames", "6", "--out", str(out), "--tets", "600", "--relative",
                 "--pin-box", "0,0,0,0.15,1,1", "--drive-box", "0.85,0,0,1,1,1", "--drive-rotate", "x,90",
                 "--young", "1e5", "--cache-dir", str(cache)])
    assert code == 0
    assert "6 frames x 5344 vertices" in capsys.readouterr().out
    poses = load_poses_npz(out)
    assert poses.vertices.shape == (6, 5344, 3) and np.all(np.isfinite(poses.vertices))
    moved = np.linalg.norm(poses.vertices[-1] - poses.vertices[0], axis=1)
    assert moved.max() > 0.3 and moved.max() < 3.0


def test_cli_reports_bad_options(bob_path, tmp_path, capsys):
    assert main(["simulate", str(bob_path), "--out", str(tmp_path / "x.npz"), "--pin-box", "1,2,3"]) == 2
    assert "--pin-box needs 6 numbers" in capsys.readouterr().err
    assert main(["simulate", str(bob_path), "--out", str(tmp_path / "x.npz"), "--drive-rotate", "x,30"]) == 2
    assert main(["simulate", str(tmp_path / "missing.obj"), "--out", str(tmp_path / "x.npz")]) == 2


def test_a_region_that_selects_nothing_is_a_parameter_error(spot_path, cache):
    scene = SceneParams(frames=2, target_tets=600, pins=[{"box": [10, 10, 10, 11, 11, 11]}])
    with pytest.raises(ParameterError, match="selects no simulation point"):
        simulate_mesh(load_mesh(spot_path), scene, cache_dir=cache)


def test_too_much_work_is_a_limit_error():
    from pdeanim.errors import LimitError
    from pdeanim.sim.grid import box_tet_mesh
    from pdeanim.sim.simulate import simulate_tets

    mesh = box_tet_mesh((1, 1, 1), (2, 2, 2))
    scene = SceneParams(frames=10_000, substeps=10_000, iterations=100)
    with pytest.raises(LimitError, match="simulation work"):
        simulate_tets(mesh, mesh.points, mesh.surface_faces(), scene)
