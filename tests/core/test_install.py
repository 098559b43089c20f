"""Install: compatible ranges in pyproject.toml (installable beside other packages), exact pins in the lock
files that setup, CI and the image install from, and the lock covering every declared requirement."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[2]


def test_dependencies_are_compatible_ranges():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for text in project["dependencies"] + project["optional-dependencies"]["dev"]:
        specs = Requirement(text).specifier
        assert not any(s.operator in ("==", "===") for s in specs), f"{text}: pin it in the lock, not here"
        assert any(s.operator == ">=" for s in specs) and any(s.operator == "<" for s in specs), \
            f"{text}: give a lower bound and an upper bound before the next breaking version"


def test_lock_files_cover_pyproject():
    proc = subprocess.run([sys.executable, str(ROOT / "script" / "lockfile.py"), "check"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    runtime = (ROOT / "requirements.lock").read_text()
    assert "numpy==" in runtime and "pytest==" not in runtime  # the image gets no test tools
    assert (ROOT / "requirements-dev.lock").read_text().splitlines()[2] == "-r requirements.lock"


def test_setup_and_image_install_from_the_lock():
    setup = (ROOT / "script" / "setup").read_text()
    assert "-r requirements-dev.lock" in setup and "-e . --no-deps" in setup
    assert "command -v npm" in setup  # no Node: setup (and so script/demo) still works, without the validator
    assert "pip install -r requirements.lock" in (ROOT / "Dockerfile").read_text()
