"""The CLI end to end on meshes and poses unlike the repository's data: valid input gives valid GLBs, bad
input
exits 2 with a message (never a traceback)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from pdeanim.cli import main
from pdeanim.gltf.validate import assert_clean, validate_many


def cli(capsys, *argv: str) -> tuple[int, str]:
    """Run ``pdeanim ARGV`` in-process; (exit code, stderr)."""
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse errors
        rc = int(exc.code or 0)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return rc, err


def sphere_poses(
    path: Path, frames: int, vertices: np.ndarray, faces: np.ndarray, moving: bool = True
) -> Path:
    """(frames, V, 3) poses of a breathing shape (constant when ``moving`` is False)."""
    scale = 1 + (0.1 * np.sin(np.arange(frames)) if moving else np.zeros(frames))
    np.savez(
        path,
        vertices=(vertices[None] * scale[:, None, None]).astype(np.float32),
        faces=faces.astype(np.int32),
    )
    return path


@pytest.fixture(scope="module")
def ico() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(1)


def test_two_components_simulate_fit_frame_export(tmp_path, capsys, ico) -> None:
    """Two separate spheres: simulate, fit, frames at 0, 1, 0.999999 and an animation, all valid GLBs."""
    other = ico.copy()
    other.apply_translation([3, 0, 0])
    trimesh.util.concatenate([ico, other]).export(tmp_path / "two.obj")
    poses, clip = tmp_path / "p.npz", tmp_path / "c.clip"
    assert cli(capsys, "simulate", tmp_path / "two.obj", "--frames", 3, "--tets", 300, "--out", poses)[0] == 0
    assert cli(capsys, "fit", poses, "--out", clip)[0] == 0
    blobs = []
    for t in ("0", "1", "0.999999"):
        out = tmp_path / f"f{t}.glb"
        assert cli(capsys, "frame", clip, "--t", t, "--out", out)[0] == 0
        blobs.append(out.read_bytes())
    assert cli(capsys, "export", clip, "--fps", 30, "--out", tmp_path / "a.glb")[0] == 0
    blobs.append((tmp_path / "a.glb").read_bytes())
    for report in validate_many(blobs):
        assert_clean(report)


@pytest.mark.parametrize(("frames", "moving", "soup", "scale"),
                         [(1, True, False, 1.0), (2, True, False, 1.0), (6, False, False, 1.0),
                          (5, True, True, 1.0), (5, True, False, 1e6), (5, True, False, 1e-6)])
def test_poses_edge_cases_fit_and_export(tmp_path, capsys, ico, frames, moving, soup, scale) -> None:
    """F = 1, F = 2, constant frames, a triangle soup, huge and tiny coordinates: finite frames, valid GLB."""
    vertices, faces = np.asarray(ico.vertices) * scale, np.asarray(ico.faces)
    if soup:
        vertices, faces = vertices[faces].reshape(-1, 3), np.arange(faces.size).reshape(-1, 3)
    poses = sphere_poses(tmp_path / "p.npz", frames, vertices, faces, moving)
    clip, frames_out, anim = tmp_path / "c.clip", tmp_path / "all.npz", tmp_path / "a.glb"
    assert cli(capsys, "fit", poses, "--out", clip)[0] == 0
    assert cli(capsys, "frame", clip, "--t", "all", "--out", frames_out)[0] == 0
    with np.load(frames_out) as data:
        got = data["vertices"]
    assert got.shape == (frames, len(vertices), 3) and np.isfinite(got).all()
    # the default target, rel-RMS 3e-3 of the first frame's diagonal, holds for the stored (rounded) clip
    d = np.linalg.norm(got.astype(np.float64) - np.load(poses)["vertices"], axis=-1)
    diag = np.linalg.norm(np.ptp(np.load(poses)["vertices"][0], axis=0))
    assert np.sqrt(np.mean(d * d)) <= 3e-3 * diag
    assert cli(capsys, "export", clip, "--out", anim)[0] == 0
    assert_clean(validate_many([anim.read_bytes()])[0])


def test_bad_inputs_exit_2_with_a_message(tmp_path, capsys, ico) -> None:
    """Empty file, unknown extension, a flat plane, NaN t, fps 0 and a huge fps: exit code 2 and a message."""
    (tmp_path / "empty.obj").write_bytes(b"")
    ico.export(tmp_path / "mesh.txt", file_type="obj")
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]]).export(
        tmp_path / "plane.obj"
    )
    out = tmp_path / "p.npz"
    for mesh, needle in (("empty.obj", "empty"), ("mesh.txt", "unsupported"), ("plane.obj", "flat")):
        rc, err = cli(capsys, "simulate", tmp_path / mesh, "--frames", 2, "--tets", 300, "--out", out)
        assert rc == 2 and needle in err
    clip = tmp_path / "c.clip"
    assert cli(capsys, "fit", sphere_poses(out, 3, np.asarray(ico.vertices), np.asarray(ico.faces)),
               "--out", clip)[0] == 0
    rc, err = cli(capsys, "frame", clip, "--t", "nan", "--out", tmp_path / "f.glb")
    assert rc == 2 and "finite" in err
    for t in ("1.5", "-0.1", "0,0.5,1.0001"):  # the clip does not loop: as the API's 422 t_out_of_range
        rc, err = cli(capsys, "frame", clip, "--t", t, "--out", tmp_path / "f.npz")
        assert rc == 2 and "[0, 1]" in err
    for fps, needle in (("0", "positive"), ("1e9", "limit")):
        rc, err = cli(capsys, "export", clip, "--fps", fps, "--out", tmp_path / "a.glb")
        assert rc == 2 and needle in err


def test_unwritable_out_exits_2_before_any_work(tmp_path, capsys, ico, monkeypatch) -> None:
    """A missing directory, a directory, and a path below a file: exit 2 with a message, checked before the
    fit (the fit is made to fail the test if it runs) and leaving no file behind."""
    import pdeanim.fit as fit

    poses = sphere_poses(tmp_path / "p.npz", 3, np.asarray(ico.vertices), np.asarray(ico.faces))
    (tmp_path / "file").write_bytes(b"x")

    def no_fit(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        raise AssertionError("the fit ran although --out cannot be written")

    monkeypatch.setattr(fit, "fit_poses", no_fit)
    for out in (tmp_path / "missing" / "c.clip", tmp_path, tmp_path / "file" / "c.clip"):
        rc, err = cli(capsys, "fit", poses, "--out", out)
        assert rc == 2 and f"--out {out}" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "p.npz"]
    rc, err = cli(capsys, "simulate", tmp_path / "missing.obj", "--out", tmp_path / "missing" / "p.npz")
    assert rc == 2 and "cannot be written" in err
