"""The compression benchmark fits the way users do: ``pdeanim fit POSES --target-rel-rms R`` at the CLI's
defaults, or every option that differs is labelled in its table (issue 22). Fast: no benchmark run."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

import compression_peers  # noqa: E402
import peers_clip  # noqa: E402


def test_the_fit_the_benchmark_runs_is_the_cli_default_or_labelled() -> None:
    cmd = peers_clip.fit_command("seq.npz", "seq.clip", 1e-3)
    assert cmd[:3] == [sys.executable, "-c", peers_clip.CHILD]
    # the installed `pdeanim` console script
    assert "from pdeanim_service.cli import main" in peers_clip.CHILD
    argv = cmd[3:]
    assert argv[:4] == ["fit", "seq.npz", "--out", "seq.clip"]
    assert float(argv[argv.index("--target-rel-rms") + 1]) == 1e-3
    diff = peers_clip.nondefault_options(argv)
    label = peers_clip.fit_label()
    for dest, value in diff.items():
        assert dest in peers_clip.FIT_LABELS, f"{dest}={value!r} differs from the CLI default unlabelled"
        assert f"{dest}={value!r} NOT the CLI default: {peers_clip.FIT_LABELS[dest]}" in label
    if not diff:
        assert "every other option at the CLI's default" in label


@pytest.mark.parametrize(("extra", "dest", "value"), [
    (("--max-segments", "256"), "max_segments", 256),
    (("--time-model", "pde"), "time_model", "pde"),
    (("--motion", "rigid"), "motion", "rigid"),
    (("--best-effort",), "best_effort", True),
])
def test_non_default_options_are_found(extra: tuple[str, ...], dest: str, value: object) -> None:
    argv = ["fit", "a.npz", "--out", "a.clip", "--target-rel-rms", "0.003", *extra]
    assert peers_clip.nondefault_options(argv) == {dest: value}
    assert peers_clip.nondefault_options(argv[:6]) == {}


def test_the_benchmark_refuses_an_unlabelled_option_before_any_work(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setattr(peers_clip, "FIT_EXTRA_ARGS", ("--max-segments", "256"))
    monkeypatch.setattr(peers_clip, "FIT_LABELS", {})
    with pytest.raises(ValueError, match="max_segments=256"):
        peers_clip.check_fit_options()
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="without a label in FIT_LABELS"):
        compression_peers.main(["--out", str(out), "--methods", "clip", "--sequences", "rig4-tube"])
    assert not out.exists()


def test_a_labelled_option_is_named_in_the_table_header(monkeypatch) -> None:
    monkeypatch.setattr(peers_clip, "FIT_EXTRA_ARGS", ("--max-segments", "256"))
    monkeypatch.setattr(peers_clip, "FIT_LABELS", {"max_segments": "the cap of the older runs"})
    label = peers_clip.fit_label()
    assert "--max-segments 256" in label
    assert "max_segments=256 NOT the CLI default: the cap of the older runs" in label
