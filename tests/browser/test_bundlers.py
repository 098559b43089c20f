"""The JS package under the bundlers people use: a page built with esbuild and with Vite decodes clips in the
package's Web Worker (fzstd bundled into it, nothing resolved at run time), and a build that left the worker
out still plays, with a console warning that says why (headless Chromium)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.browser.test_viewer import browser_ready  # noqa: F401  (fixture: fails under CI when tools are missing)

HERE = Path(__file__).resolve().parent
CLIP = HERE.parents[1] / "clients" / "js" / "test" / "fixtures" / "fit-displacement-chord.clip"
N_VERTICES = 42


BUILDS = ["esbuild", "vite", "esbuild-without-worker"]


@pytest.fixture(scope="module")
def seen(browser_ready) -> dict:  # noqa: F811
    """What each build's page saw, from one Chromium for the module."""
    for tool in ("esbuild", "vite"):
        assert (HERE / "node_modules" / tool).is_dir(), f"{tool} is not installed: npm ci in tests/browser"
    proc = subprocess.run(["node", str(HERE / "bundle_check.mjs"), str(CLIP), *BUILDS], cwd=HERE,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("bundler", ["esbuild", "vite"])
def test_a_bundled_page_decodes_in_the_worker(seen, bundler):
    page = seen[bundler]
    assert "error" not in page, page["error"]
    assert page["nVertices"] == N_VERTICES
    assert page["workerNames"] == ["pdeanim-decoder"], page
    assert page["warnings"] == []


def test_a_build_without_the_worker_warns_and_still_decodes(seen):
    page = seen["esbuild-without-worker"]
    assert "error" not in page, page["error"]
    assert page["nVertices"] == N_VERTICES
    assert page["workerNames"] == []
    assert len(page["warnings"]) == 1, page["warnings"]
    assert "decoding clips on the main thread" in page["warnings"][0]
    assert "did not start" in page["warnings"][0]
