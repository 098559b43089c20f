"""Progress on stderr for long `simulate`, `fit` and `export` runs, silent with --quiet."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from pdeanim.cli import main
from pdeanim.progress import StderrProgress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_terminal_redraws_one_line_and_log_gets_lines():
    tty = Terminal()
    bar = StderrProgress("pdeanim fit", tty)
    for k in range(3):
        bar(k / 2, f"fit {k}/2")
    bar.close()
    text = tty.getvalue()
    assert text.startswith("\rpdeanim fit: fit 0/2") and text.endswith("\n") and text.count("\n") == 1
    log = io.StringIO()
    bar = StderrProgress("pdeanim fit", log, log_every=0.0)
    bar(0.5, "fit 1/2")
    bar(1.0, "fit 2/2")
    bar.close()
    lines = log.getvalue().splitlines()
    assert len(lines) == 2 and all(line.startswith("pdeanim fit: fit") for line in lines)
    assert "100.0%" in lines[-1]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("progress")
    trimesh.creation.icosphere(1).export(d / "ball.obj")
    return d


@pytest.mark.parametrize("quiet", [False, True])
def test_commands_report_progress_unless_quiet(files, tmp_path, capsys, monkeypatch, quiet):
    monkeypatch.setenv("PDEANIM_PROGRESS_EVERY", "0")  # a line per report: the runs here are short
    q = ["--quiet"] if quiet else []
    poses, clip, glb = tmp_path / "p.npz", tmp_path / "c.clip", tmp_path / "a.glb"
    steps = {"simulate": ["simulate", files / "ball.obj", "--frames", 4, "--tets", 200, "--out", poses],
             "fit": ["fit", poses, "--out", clip], "export": ["export", clip, "--out", glb]}
    for command, argv in steps.items():
        assert main([str(a) for a in argv] + q) == 0
        err = capsys.readouterr().err
        if quiet:
            assert err == "", err
        else:
            lines = err.splitlines()
            assert lines and all(line.startswith(f"pdeanim {command}: ") for line in lines), err
            assert "%" in lines[-1]
    assert np.load(poses)["vertices"].shape[0] == 4 and glb.stat().st_size > 0
