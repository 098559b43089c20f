"""pdeanim fit / pdeanim frame through the console entry point."""

from __future__ import annotations

import contextlib
import io
import re

import numpy as np
import pytest

from pdeanim import container
from pdeanim.cli import main
from pdeanim.clip import load_clip_file, read_clip_file
from pdeanim.poses import make_poses, save_poses
from tests.triangles import same_triangles


@pytest.fixture(scope="module")
def poses_file(tmp_path_factory, morph_poses):
    path = tmp_path_factory.mktemp("cli") / "poses.npz"
    p = morph_poses
    save_poses(path, make_poses(p.vertices[::6], p.faces, p.times[::6]))
    return path


@pytest.fixture(scope="module")
def fit_run(poses_file) -> tuple:
    """``pdeanim fit`` once for the module: the clip path and what the command printed."""
    out = poses_file.parent / "x.clip"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["fit", str(poses_file), "--out", str(out), "--target-rel-rms", "3e-3"]) == 0
    return out, printed.getvalue()


@pytest.fixture(scope="module")
def clip_file(fit_run):
    return fit_run[0]


def test_fit_meets_target_and_prints_summary(fit_run, poses_file):
    clip_file, printed = fit_run
    errors = load_clip_file(clip_file).info()["errors"]
    assert errors["rel_rms"] <= 3e-3 and errors["target_met"] is True
    frames, vertices = np.load(poses_file)["vertices"].shape[:2]
    parts = read_clip_file(clip_file)
    lines = printed.splitlines()
    assert lines[0].startswith(f"fitted {frames} frames x {vertices} vertices with ")
    assert f"(rel {errors['rel_rms']:.3g})" in lines[1]
    assert lines[2].endswith(": met")
    assert lines[3].startswith(f"bytes: topology {len(parts.topology)}, "
                               f"coefficients {len(parts.coefficients)}, "
                               f"raw float32 {frames * vertices * 12} ")
    version = container.unpack(parts.coefficients)[0]["format_version"]
    assert f"), format {version}" in lines[3]
    assert lines[4].startswith("time models (curve coordinates): natural spline ")
    assert lines[5].startswith("time ") and lines[5].endswith(f" s -> {clip_file}")


def test_frame_single_list_and_all(clip_file, poses_file, tmp_path):
    data = np.load(poses_file)
    out = tmp_path / "f.npz"
    assert main(["frame", str(clip_file), "--t", "0.37", "--out", str(out)]) == 0
    with np.load(out) as f:
        assert f["vertices"].shape == (data["vertices"].shape[1], 3)
        assert same_triangles(f["faces"], data["faces"])  # version 2 keeps them in a canonical order
    assert main(["frame", str(clip_file), "--t", "0,0.5,1", "--out", str(out)]) == 0
    with np.load(out) as f:
        assert f["vertices"].shape == (3, data["vertices"].shape[1], 3)
    assert main(["frame", str(clip_file), "--t", "all", "--out", str(out)]) == 0
    with np.load(out) as f:
        v = f["vertices"]
        assert v.shape == data["vertices"].shape
        diag = np.linalg.norm(data["vertices"][0].max(0) - data["vertices"][0].min(0))
        rms = np.sqrt(np.mean(np.sum((v - data["vertices"]) ** 2, axis=-1)))
        assert rms / diag <= 3e-3


def test_bad_arguments_exit_2(clip_file, poses_file, tmp_path, capsys):
    assert main(["frame", str(clip_file), "--t", "abc", "--out", str(tmp_path / "f.npz")]) == 2
    assert main(["frame", str(clip_file), "--t", "0.1", "--out", str(tmp_path / "f.txt")]) == 2
    assert (
        main(["frame", str(tmp_path / "missing.clip"), "--t", "0.1", "--out", str(tmp_path / "f.npz")]) == 2
    )
    assert main(["fit", str(poses_file), "--out", str(tmp_path / "y.clip"), "--segments", "0"]) == 2
    assert "error" in capsys.readouterr().err


def test_fixed_segments_fit(poses_file, tmp_path, capsys):
    out = tmp_path / "s.clip"
    assert main(["fit", str(poses_file), "--out", str(out), "--segments", "3", "--motion", "absolute"]) == 0
    assert load_clip_file(out).info()["n_segments"] == 3
    assert "segments" in capsys.readouterr().out


def test_missed_target_exits_3_after_writing_the_best_clip(poses_file, tmp_path, capsys, monkeypatch):
    """A target the segment cap cannot reach: exit 3, the clip is still written, stderr says achieved vs asked
    and that the cap stopped the search; --best-effort exits 0 with the same message."""
    monkeypatch.setenv("PDEANIM_PROGRESS_EVERY", "0")  # a progress line per report (stderr is not a terminal)
    out = tmp_path / "capped.clip"
    args = ["fit", str(poses_file), "--out", str(out), "--target-rel-rms", "1e-6", "--max-segments", "1"]
    assert main(args) == 3
    err = capsys.readouterr().err
    assert "target not met" in err and "segment cap" in err and "rel 1e-06" in err
    progress = re.compile(r"^pdeanim fit: .* +\d+\.\d% \(\d+ s\)$")  # the StderrProgress line format
    assert any(progress.match(line) for line in err.splitlines())
    info = load_clip_file(out).info()
    assert info["n_segments"] == 1 and info["errors"]["target_met"] is False
    assert main([*args, "--best-effort", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "target not met" in err and not any(progress.match(line) for line in err.splitlines())


def test_segment_cap_defaults_to_the_library_default(capsys):
    """Without --max-segments the CLI leaves FitOptions' cap alone, and its help names that default."""
    from pdeanim.fit import FitOptions
    from pdeanim.model.segments import DEFAULT_MAX_SEGMENTS

    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert FitOptions().max_segments == DEFAULT_MAX_SEGMENTS
    assert f"(default {DEFAULT_MAX_SEGMENTS}, FitOptions.max_segments" in help_text


def test_fit_in_the_streamable_layout(poses_file, tmp_path, monkeypatch, capsys):
    """``--layout stream``: the clip of the same fit in the streamable layout (format 1.2, docs/format.md
    §3.10), one window per --max-window-segments segments; it plays as the one-piece clip does."""
    from pdeanim import container

    whole, stream = tmp_path / "w.clip", tmp_path / "s.clip"
    assert main(["fit", str(poses_file), "--out", str(whole), "--segments", "4", "--bones", "0"]) == 0
    assert main(["fit", str(poses_file), "--out", str(stream), "--segments", "4", "--bones", "0",
                 "--layout", "stream", "--max-window-segments", "2", "--tangent-bits", "16"]) == 0
    header = container.read_header(read_clip_file(stream).coefficients)
    assert header["required"] == ["stream"] and header["stream"]["n_windows"] == 2
    a, b = load_clip_file(whole), load_clip_file(stream)
    t = np.linspace(0.0, 1.0, 21)
    np.testing.assert_allclose(b.evaluate(t), a.evaluate(t), rtol=0, atol=1e-5)
    import pdeanim.fit

    def no_fit(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        raise AssertionError("a bad window option must be refused before the fit starts")

    monkeypatch.setattr(pdeanim.fit, "fit_poses", no_fit)
    for bad in (["--tangent-bits", "31"], ["--window-seconds", "0"], ["--max-window-segments", "0"]):
        assert main(["fit", str(poses_file), "--out", str(stream), "--layout", "stream", *bad]) == 2
        assert bad[0] in capsys.readouterr().err
