"""schemathesis over the committed ``openapi/openapi.json`` against a real ``pdeanim serve`` with a real key:
every check (``--checks all``), at least 2000 generated requests, no 5xx and no undocumented status."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from .conftest import open_backend
from .harness import ROOT, Services, make_key

pytestmark = pytest.mark.slow
MIN_REQUESTS = 2000
BUDGET_SECONDS = 120  # the fuzzing and stateful phases repeat until this is spent (about 4000+ cases here)


@pytest.fixture
def services(tmp_path, request):
    """The server on the embedded backend (the routes are the same on PostgreSQL; the run takes minutes)."""
    with open_backend("sqlite", tmp_path / "data", request) as backend:
        # short long-polls: generated ?wait= values would otherwise hold each request for the default 30 s
        svc = Services(backend, tmp_path, env_extra={"PDEANIM_MAX_WAIT_SECONDS": "0.5",
                                                     "PDEANIM_MAX_UPLOAD_BYTES": "2000000"})
        svc.start_server()
        yield svc
        svc.stop()


def test_schemathesis_finds_no_server_error_and_no_undocumented_status(services, tmp_path):
    key = make_key(services.backend, "fuzz")
    cmd = [sys.executable, "-m", "schemathesis.cli", "--config-file", str(ROOT / "tests/service/schemathesis.toml"),
           "run", str(ROOT / "openapi/openapi.json"), "--url", services.url, "-H", f"Authorization: Bearer {key}",
           "--checks", "all", "--max-examples", "25", "--workers", "2", "--max-time", str(BUDGET_SECONDS),
           "--seed", "20261126", "--generation-database", "none", "--no-color"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=BUDGET_SECONDS * 4, cwd=tmp_path)
    report = out.stdout + out.stderr
    generated = re.search(r"(\d+) generated", report)
    assert out.returncode == 0, report[-12000:] + "\n" + services.logs()[-4000:]
    assert generated and int(generated.group(1)) >= MIN_REQUESTS, report[-3000:]
    assert "Traceback" not in services.logs(), services.logs()[-4000:]
