"""``pdeanim cyclic`` on a generated fish."""

from __future__ import annotations

import numpy as np
import pytest

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


GAIT_CASES = [("biped", "walk"), ("biped", "run"), ("quadruped", "walk"), ("quadruped", "trot"),
              ("quadruped", "pace"), ("quadruped", "canter"), ("quadruped", "gallop"), ("hexapod", "tripod"),
              ("hexapod", "wave")]


def _rig_file(tmp_path, name: str):
    from .rig import BIPED, HEXAPOD, QUADRUPED, rig_glb

    path = tmp_path / f"{name}.glb"
    path.write_bytes(rig_glb({"biped": BIPED, "quadruped": QUADRUPED, "hexapod": HEXAPOD}[name]))
    return path


@pytest.mark.parametrize(("rig", "gait"), GAIT_CASES)
def test_cli_gait_clip_of_every_rig(tmp_path, capsys, rig, gait):
    out = tmp_path / f"{gait}.clip"
    rc = main(["cyclic", str(_rig_file(tmp_path, rig)), "--mode", gait, "--frames", "12", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "legs: " in text and f"{gait} cycle: 13 frames" in text and "soles slide at most" in text
    clip = load_clip_file(out)
    assert clip.looping and np.array_equal(clip.evaluate(0.0), clip.evaluate(1.0))
    assert clip.info()["gait"]["name"] == gait and clip.info()["travel"]["speed"] > 0


def test_cli_gait_glb_poses_and_picture(tmp_path, capsys, data_dir):
    from pdeanim.gltf.validate import validate_many
    from pdeanim.poses import load_poses_npz

    fox = str(data_dir / "Fox.glb")
    rc = main(["cyclic", fox, "--mode", "trot", "--out", str(tmp_path / "trot.glb"), "--plot",
               str(tmp_path / "trot.png"), "--set", "step_length=0.25", "--set", "duty=0.55"])
    text = capsys.readouterr().out
    assert rc == 0 and "hind-left (b_LeftFoot02_018, 3 bones)" in text and "plot: " in text
    assert (tmp_path / "trot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    hexa = str(_rig_file(tmp_path, "hexapod"))
    rc = main(["cyclic", hexa, "--mode", "wave", "--frames", "12", "--out", str(tmp_path / "wave.npz")])
    assert rc == 0
    poses = load_poses_npz(tmp_path / "wave.npz")
    assert poses.vertices.shape[0] == 13 and np.array_equal(poses.vertices[-1], poses.vertices[0])
    biped = str(_rig_file(tmp_path, "biped"))
    rc = main(["cyclic", biped, "--mode", "run", "--out", str(tmp_path / "run.glb"), "--set", "literal=true",
               "--right-foot", "foot.R", "--hip", "hip"])
    assert rc == 0 and "run cycle" in capsys.readouterr().out
    reports = validate_many([(tmp_path / n).read_bytes() for n in ("trot.glb", "run.glb")])
    assert [(r["issues"]["numErrors"], r["issues"]["numWarnings"]) for r in reports] == [(0, 0), (0, 0)]


@pytest.mark.parametrize(("args", "message"), [
    (["--mode", "tripod"], "the tripod gait needs six or more legs"),
    (["--mode", "trot", "--set", "stride=1"], "unknown gait parameter"),
    (["--mode", "trot", "--set", "step_length"], "KEY=VALUE"),
    (["--mode", "trot", "--legs", "toe.L"], "no joint named 'toe.L'"),
    (["--mode", "trot", "--set", "step_length=3"], "stride is longer than the legs reach"),
    (["--mode", "walk", "--left-foot", "front.L.2"], "two-legged character"),
    (["--mode", "walk", "--out-ext", ".clip2"], "must be a .clip"),
])
def test_cli_gait_errors(tmp_path, capsys, args, message):
    quad = str(_rig_file(tmp_path, "quadruped"))
    out = str(tmp_path / ("x.clip2" if "--out-ext" in args else "x.clip"))
    args = [a for a in args if a not in ("--out-ext", ".clip2")]
    assert main(["cyclic", quad, *args, "--out", out]) == 2
    assert message in capsys.readouterr().err


def test_cli_no_legs_names_the_joints(tmp_path, capsys, data_dir):
    rc = main(["cyclic", str(data_dir / "fish_eel.obj"), "--mode", "trot", "--out", str(tmp_path / "x.clip")])
    assert rc == 2 and "skinned" in capsys.readouterr().err.lower()
    from .rig import Rig, rig_glb

    snake = tmp_path / "snake.glb"
    snake.write_bytes(rig_glb(Rig([("s0", -1, (0.0, 0.2, 0.0)), ("s1", 0, (0.0, 0.0, 0.4))], ())))
    rc = main(["cyclic", str(snake), "--mode", "walk", "--out", str(tmp_path / "x.clip")])
    err = capsys.readouterr().err
    assert rc == 2 and "no legs found" in err and "s0" in err and "s1" in err
