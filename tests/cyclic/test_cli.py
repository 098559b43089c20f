"""``pdeanim cyclic`` on a generated fish."""

from __future__ import annotations

import numpy as np

from pdeanim.cli import main
from pdeanim.clip import load_clip_file


def test_cli_writes_a_looping_clip(tmp_path, data_dir, capsys):
    out = tmp_path / "eel.clip"
    png = tmp_path / "eel.png"
    rc = main(["cyclic", str(data_dir / "fish_eel.obj"), "--mode", "eel", "--out", str(out), "--curves", "19",
               "--amplitude", "0.1", "--wave", "travelling", "--plot", str(png)])
    text = capsys.readouterr().out
    assert rc == 0
    assert "curves: 19" in text and "bytes: coefficients" in text and "rest-pose distance" in text
    clip = load_clip_file(out)
    assert clip.looping and clip.params.amplitude == 0.1 and clip.params.wave == "travelling"
    assert np.abs(clip.evaluate(1.0) - clip.evaluate(0.0)).max() < 1e-6
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_reports_bad_input(tmp_path, data_dir, capsys):
    rc = main(["cyclic", str(data_dir / "fish_eel.obj"), "--mode", "cod", "--out", str(tmp_path / "x.clip")])
    assert rc == 2 and "unknown swim mode" in capsys.readouterr().err
    rc = main(["cyclic", str(data_dir / "AnimatedMorphSphere.npz"), "--out", str(tmp_path / "x.clip")])
    assert rc == 2


def test_cli_walk_cycle_of_a_skinned_rig(tmp_path, capsys):
    from pdeanim.poses import load_poses_npz

    from .rig import rig_glb

    rig = tmp_path / "rig.glb"
    rig.write_bytes(rig_glb())
    rc = main(["cyclic", str(rig), "--mode", "walk", "--frames", "12", "--out", str(tmp_path / "walk.npz")])
    assert rc == 0 and "walk cycle: 13 frames" in capsys.readouterr().out
    poses = load_poses_npz(tmp_path / "walk.npz")
    assert np.abs(poses.vertices[-1] - poses.vertices[0]).max() < 1e-5
    rc = main(
        [
            "cyclic",
            str(rig),
            "--mode",
            "run",
            "--out",
            str(tmp_path / "run.glb"),
            "--set",
            "step_height=0.2",
            "--set",
            "literal=true",
            "--right-foot",
            "foot.R",
        ]
    )
    assert rc == 0 and (tmp_path / "run.glb").read_bytes()[:4] == b"glTF"
    rc = main(["cyclic", str(rig), "--mode", "walk", "--out", str(tmp_path / "walk.clip")])
    assert rc == 2
    rc = main(["cyclic", str(rig), "--mode", "walk", "--set", "stride=1", "--out", str(tmp_path / "w.npz")])
    assert rc == 2
