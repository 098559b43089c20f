"""Audit defect 8, the small ones in the library: t far outside [0, 1] on looping clips, OBJ coordinates that
overflow, and the demo mesh shipped with the package."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.clip import load_clip
from pdeanim.errors import MeshInputError
from pdeanim.mesh.io import load_mesh


@pytest.fixture(scope="module")
def cyclic_clip(data_dir):
    from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip

    options = {"mode": "eel", "frames": 12, "n_curves": 21, "points": 24, "modes": 4}
    parts = make_cyclic_clip(load_mesh(data_dir / "fish_eel.obj"), CyclicOptions.from_dict(options))
    return load_clip(parts.topology, parts.coefficients)


@pytest.fixture(scope="module")
def looping_fit_clip():
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.poses import make_poses

    base = np.random.default_rng(1).normal(size=(30, 3))
    phase = np.linspace(0, 2 * np.pi, 13)[:-1]
    frames = base[None] * (1 + 0.1 * np.sin(phase))[:, None, None]
    parts = fit_poses(make_poses(frames, None), FitOptions(loop=True))
    return load_clip(parts.topology, parts.coefficients)


@pytest.mark.parametrize("t", [1e308, -1e308, 1e17 + 0.25, 123456.25, -3.75])
@pytest.mark.parametrize("which", ["cyclic_clip", "looping_fit_clip"])
def test_looping_clip_any_finite_t(request, which, t):
    """t on a looping clip is reduced modulo the period first: huge t gives the frame at t mod 1."""
    clip = request.getfixturevalue(which)
    assert clip.looping
    got = clip.evaluate(t)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, clip.evaluate(float(np.mod(t, 1.0))), atol=1e-5)
    many = clip.evaluate(np.array([t, 0.5]))
    np.testing.assert_allclose(many[0], got, atol=1e-5)


def test_obj_with_overflowing_coordinates(tmp_path):
    """1e308-sized coordinates are finite but their extent overflows: a clear error, not 'surface is flat'."""
    path = tmp_path / "huge.obj"
    path.write_text("v 0 0 0\nv 1e308 0 0\nv 0 1e308 0\nv 0 0 -1e308\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    with pytest.raises(MeshInputError, match="overflow|too large|non-finite") as info:
        load_mesh(path).stats()
    assert "flat" not in str(info.value)


@pytest.mark.parametrize("argv", [["fit", "{poses}"], ["frame", "{clip}", "--t", "0"], ["export", "{clip}"],
                                  ["simulate", "{mesh}"], ["cyclic", "{mesh}"]])
def test_out_into_missing_directory_is_checked_first(tmp_path, capsys, argv):
    """`--out` into a missing directory: exit 2 naming the directory, checked before the input is even read
    (the inputs here do not exist, and the error is still about --out)."""
    from pdeanim.cli import main

    names = {"poses": tmp_path / "p.npz", "clip": tmp_path / "c.clip", "mesh": tmp_path / "m.obj"}
    args = [a.format(**names) for a in argv] + ["--out", str(tmp_path / "absent_dir" / "out.glb")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "absent_dir" in err and "Traceback" not in err, err


def test_demo_mesh_ships_in_the_wheel(tmp_path):
    """`pdeanim demo` needs no checkout: its sample mesh (with its license line) is package data, and the
    demo's default points at the installed copy."""
    import subprocess
    import sys
    import zipfile
    from pathlib import Path

    from pdeanim_service.demo import SAMPLE_MESH

    root = Path(__file__).resolve().parents[2]
    assert SAMPLE_MESH.is_file() and "tests" not in SAMPLE_MESH.relative_to(root).parts
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(tmp_path), str(root)], check=True, capture_output=True, timeout=600)
    wheel = next(tmp_path.glob("pdeanim-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "pdeanim/data/spot.obj" in names and "pdeanim/data/LICENSES.md" in names, sorted(names)[:20]
    assert load_mesh(SAMPLE_MESH).stats()["vertices"] > 1000
