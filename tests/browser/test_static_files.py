"""The browser files the service ships: in sync with their sources (npm packages, clients/js/src), with the
licenses of the vendored libraries next to them, and nothing loaded from another host."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STATIC = ROOT / "service" / "api" / "static"
VENDOR_SCRIPT = ROOT / "tools" / "web-vendor" / "vendor.py"


def test_vendored_files_match_their_sources():
    out = subprocess.run([sys.executable, str(VENDOR_SCRIPT), "--check"], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_vendored_libraries_carry_their_licenses_and_pinned_versions():
    versions = json.loads((STATIC / "vendor" / "versions.json").read_text())
    assert set(versions) == {"three", "fzstd", "swagger-ui-dist", "redoc"}
    package = json.loads((ROOT / "tools" / "web-vendor" / "package.json").read_text())
    assert package["dependencies"] == versions  # exact pins, so the copies are reproducible
    # the viewer ships the fzstd the JS client is tested with (its one runtime dependency)
    client_lock = json.loads((ROOT / "clients" / "js" / "package-lock.json").read_text())
    assert client_lock["packages"]["node_modules/fzstd"]["version"] == versions["fzstd"]
    licenses = (("three", "MIT License"), ("fzstd", "MIT License"), ("redoc", "MIT License"),
                ("swagger-ui", "Apache License"))
    for folder, words in licenses:
        assert words in (STATIC / "vendor" / folder / "LICENSE").read_text()


def test_pages_load_nothing_from_other_hosts():
    for path in (STATIC / "viewer").rglob("*"):
        if path.suffix in (".html", ".js", ".mjs", ".css"):
            text = path.read_text()
            assert not re.search(r"""(?:src|href|from|import)\s*\(?\s*["']https?://""", text), path
