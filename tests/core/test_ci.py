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
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    assert "export CI=true" in lines
    assert lines.index("export CI=true") < next(i for i, line in enumerate(lines) if "script/test" in line)
