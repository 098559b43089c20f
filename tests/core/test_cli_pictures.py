"""`pdeanim fit --pictures DIR` draws where the fit struggles: worst-frame error mesh and error per frame."""

from __future__ import annotations

import numpy as np
from PIL import Image

from pdeanim.cli import main
from pdeanim.clip import load_clip_file
from pdeanim.poses import load_poses_npz, make_poses, save_poses


def test_fit_writes_error_pictures(tmp_path, morph_sphere_path, capsys):
    full = load_poses_npz(morph_sphere_path)
    poses = make_poses(full.vertices[:40], full.faces, full.times[:40])
    save_poses(tmp_path / "p.npz", poses)
    code = main(["fit", str(tmp_path / "p.npz"), "--out", str(tmp_path / "c.clip"), "--segments", "3",
                 "--pictures", str(tmp_path / "pics")])
    assert code == 0
    out = capsys.readouterr().out
    clip = load_clip_file(tmp_path / "c.clip")
    err = np.linalg.norm(clip.evaluate(np.linspace(0, 1, 40)) - poses.vertices, axis=-1).max(axis=1)
    worst = int(err.argmax())  # the fit's worst frame, recomputed from the clip file
    with Image.open(tmp_path / "pics" / "c_error_curve.png") as im:
        assert im.text["Description"] == f"worst frame {worst}"
    with Image.open(tmp_path / "pics" / "c_worst_frame.png") as im:
        assert f"at frame {worst} " in im.text["Title"]
    for name in ("c_worst_frame.png", "c_error_curve.png"):
        path = tmp_path / "pics" / name
        assert f"picture -> {path}" in out
        with Image.open(path) as im:
            assert im.format == "PNG" and im.width > 300 and im.height > 200
            # a real drawing, not a blank canvas: several distinct colours
            assert len(np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)) > 50
