"""Run the Khronos glTF-Validator (npm package ``gltf-validator``, see ``tools/gltf-validator``) on GLB bytes.

The validator is a JavaScript library, so this module runs ``node validate.js`` and parses the JSON report.
``script/setup`` installs it (``npm ci`` in ``tools/gltf-validator``). Override the locations with the
environment variables ``PDEANIM_NODE`` (node executable) and ``PDEANIM_GLTF_VALIDATOR_DIR`` (folder holding
``validate.js`` and ``node_modules/gltf-validator``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

from ..errors import PdeanimError

TOOL_DIR = Path(__file__).resolve().parents[2] / "tools" / "gltf-validator"
SEVERITIES = {0: "error", 1: "warning", 2: "info", 3: "hint"}


class ValidatorUnavailable(PdeanimError):
    """node or the gltf-validator package is not installed where expected."""

    code = "validator_unavailable"


class ValidatorFailed(PdeanimError):
    """The validator could not produce a report (e.g. the bytes are not glTF at all)."""

    code = "validator_failed"


def validator_command() -> list[str]:
    """The command line prefix ``[node, validate.js]``; raises ValidatorUnavailable naming what is missing."""
    node = shutil.which(os.environ.get("PDEANIM_NODE") or "node")
    if not node:
        raise ValidatorUnavailable("node is not installed (needed for the glTF validator); install Node.js "
                                   "or set PDEANIM_NODE to its path")
    tool = Path(os.environ.get("PDEANIM_GLTF_VALIDATOR_DIR") or TOOL_DIR)
    script = tool / "validate.js"
    if not script.is_file():
        raise ValidatorUnavailable(f"{script} is missing")
    if not (tool / "node_modules" / "gltf-validator").is_dir():
        raise ValidatorUnavailable(f"the npm package gltf-validator is not installed in {tool}; "
                                   f"run `npm ci` there (script/setup does it)")
    return [node, str(script)]


def _run(args: list[str], stdin: bytes | None, timeout: float) -> object:
    cmd = validator_command() + args
    try:
        proc = subprocess.run(cmd, input=stdin, capture_output=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise ValidatorFailed(f"glTF validator did not run: {exc}") from exc
    if proc.returncode != 0:
        msg = proc.stderr.decode("utf-8", "replace").strip().splitlines()
        raise ValidatorFailed(f"glTF validator failed: {msg[0] if msg else f'exit {proc.returncode}'}")
    return json.loads(proc.stdout)


def validate_glb(data: bytes, timeout: float = 120.0) -> dict:
    """The validator's report (``issues.numErrors``, ``issues.messages``, ``info``...) for GLB bytes."""
    report = _run([], bytes(data), timeout)
    assert isinstance(report, dict)
    return report


def validate_many(blobs: Sequence[bytes], timeout: float = 300.0) -> list[dict]:
    """Reports for several GLBs with one node start (faster in test suites); same order as ``blobs``."""
    if not blobs:
        return []
    with tempfile.TemporaryDirectory(prefix="pdeanim-gltf-") as tmp:
        paths = []
        for i, blob in enumerate(blobs):
            path = Path(tmp) / f"asset{i}.glb"
            path.write_bytes(bytes(blob))
            paths.append(str(path))
        out = _run(paths, None, timeout)
    return [out] if len(blobs) == 1 else list(out)  # type: ignore[arg-type]


def issue_lines(report: dict, severities: Sequence[int] = (0, 1, 2, 3)) -> list[str]:
    """Readable one-line descriptions of the report's messages of the given severities."""
    lines = []
    for m in report.get("issues", {}).get("messages", []):
        if m.get("severity") in severities:
            where = m.get("pointer") or (f"offset {m['offset']}" if "offset" in m else "")
            lines.append(f"{SEVERITIES.get(m.get('severity'), '?')} {m.get('code')}: {m.get('message')} "
                         f"{where}")
    return lines


def assert_clean(report: dict, label: str = "GLB") -> dict:
    """Raise AssertionError unless the report has 0 errors and 0 warnings; infos and hints are printed."""
    issues = report.get("issues", {})
    soft = issue_lines(report, (2, 3))
    if soft:
        print(f"{label}: validator infos/hints:\n  " + "\n  ".join(soft))
    if issues.get("numErrors", 1) or issues.get("numWarnings", 1):
        raise AssertionError(
            f"{label} is not validator-clean ({issues.get('numErrors')} errors, "
            f"{issues.get('numWarnings')} warnings):\n  " + "\n  ".join(issue_lines(report, (0, 1)))
        )
    return report


def assert_glb_clean(data: bytes, label: str = "GLB") -> dict:
    """Validate GLB bytes and assert 0 errors and 0 warnings (the test helper); returns the report."""
    return assert_clean(validate_glb(data), label)
