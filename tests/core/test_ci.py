"""Under CI a missing service fails the run; elsewhere it skips with the reason; ``.ci/run`` sets CI."""

from __future__ import annotations

from pathlib import Path

import pytest

from ..ci import in_ci, missing

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(("value", "ci"), [("true", True), ("TRUE", True), ("1", True), ("yes", True),
                                           ("", False), ("false", False), ("0", False)])
def test_missing_fails_under_ci_and_skips_elsewhere(monkeypatch, value, ci):
    monkeypatch.setenv("CI", value)
    assert in_ci() is ci
    with pytest.raises(pytest.fail.Exception if ci else pytest.skip.Exception, match="PostgreSQL is down"):
        missing("PostgreSQL is down")


def test_ci_entry_point_exports_ci_true():
    lines = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if not line.startswith("#")]
    assert "export CI=true" in lines
    assert lines.index("export CI=true") < next(i for i, line in enumerate(lines) if "script/test" in line)


def test_ci_leaves_the_slow_tests_to_the_nightly_script_and_prints_its_times():
    """CI runs ``-m "not slow"`` (the marker is registered), script/test-nightly runs ``-m slow``, and the run
    ends with its wall time."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert any(m.startswith("slow:") for m in config["markers"])
    test = (ROOT / "script" / "test").read_text()
    assert 'select=(-m "not slow")' in test and '${select[@]+"${select[@]}"} "$@"' in test
    assert "pytest -m slow" in (ROOT / "script" / "test-nightly").read_text()
    assert "wall time" in (ROOT / ".ci" / "run").read_text().splitlines()[-2]
