"""The validator harness: reports for good and bad bytes, clear errors when node or the package is missing."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.gltf.validate import (
    ValidatorFailed,
    ValidatorUnavailable,
    assert_clean,
    assert_glb_clean,
    validate_glb,
)
from pdeanim.gltf.write import frame_glb


def test_clean_report_for_a_written_frame():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    report = assert_glb_clean(frame_glb(p, np.array([[0, 1, 2]])), "triangle")
    assert report["issues"]["numErrors"] == 0 and report["info"]["totalVertexCount"] == 3


def test_defects_are_reported_and_asserted():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    glb = bytearray(frame_glb(p, np.array([[0, 1, 2]])))
    glb[8:12] = (len(glb) + 4).to_bytes(4, "little")  # header length no longer matches the file
    report = validate_glb(bytes(glb))
    assert report["issues"]["numErrors"] >= 1
    with pytest.raises(AssertionError, match="not validator-clean"):
        assert_clean(report, "broken")
    with pytest.raises(ValidatorFailed):
        validate_glb(b"neither glb nor json")


def test_missing_validator_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("PDEANIM_GLTF_VALIDATOR_DIR", str(tmp_path))
    with pytest.raises(ValidatorUnavailable, match="validate.js"):
        validate_glb(b"glTF")
    monkeypatch.setenv("PDEANIM_NODE", str(tmp_path / "no-node-here"))
    monkeypatch.delenv("PDEANIM_GLTF_VALIDATOR_DIR")
    with pytest.raises(ValidatorUnavailable, match="node is not installed"):
        validate_glb(b"glTF")
