"""docs/architecture.md stays the map of the code: its module tables name every module of the library, the
service and the worker, each in the row of its folder, and no module that does not exist."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
SKIPPED = ("service/store/migrations/",)  # Alembic's environment and revisions, named as "the migrations"


def _rows() -> dict[str, set[str]]:
    """Folder (``pdeanim/fit/``; ``pdeanim/`` for the library's "top level" row) -> the ``*.py`` names of its
    row in the doc's module tables."""
    rows: dict[str, set[str]] = {}
    for line in DOC.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 2 or not line.startswith("| "):
            continue
        key = cells[0].strip("`")
        if key == "top level":
            folder = "pdeanim/"
        elif key.endswith("/") and not key.startswith(("service", "worker")):
            folder = f"pdeanim/{key}"
        elif key.endswith("/"):
            folder = key
        else:
            continue
        names = set(re.findall(r"`([\w]+\.py)`", cells[1]))
        if names:
            rows[folder] = names
    return rows


def _modules() -> dict[str, set[str]]:
    """Folder -> the module files in it (package __init__s and SKIPPED aside)."""
    found: dict[str, set[str]] = {}
    for pkg in ("pdeanim", "service", "worker"):
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).as_posix()
            if path.name == "__init__.py" or rel.startswith(SKIPPED):
                continue
            found.setdefault(rel.rpartition("/")[0] + "/", set()).add(path.name)
    return found


def test_every_module_is_in_its_folders_row_and_every_named_module_exists():
    rows, modules = _rows(), _modules()
    missing = sorted(f"{folder}{name}" for folder, names in modules.items()
                     for name in names - rows.get(folder, set()))
    assert missing == [], f"docs/architecture.md does not name {missing}"
    absent = sorted(f"{folder}{name}" for folder, names in rows.items()
                    for name in names - modules.get(folder, set()))
    assert absent == [], f"docs/architecture.md names modules that do not exist: {absent}"


def test_the_check_sees_the_tables():
    rows = _rows()
    assert {"pdeanim/", "pdeanim/fit/", "pdeanim/model/", "service/api/", "worker/"} <= set(rows)
    assert "windowed.py" in rows["pdeanim/fit/"] and "queue.py" in rows["service/store/"]


def test_no_round_by_round_wording():
    for path in (ROOT / "README.md", DOC):
        assert "this round" not in path.read_text().lower(), path
