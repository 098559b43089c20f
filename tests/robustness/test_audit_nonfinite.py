"""Audit defect 4: non-finite metrics never reach JSON. A clip whose KG error is undefined (every vertex at
one point, so the KG denominator is 0) reports it as null, and containers refuse NaN/inf in their headers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pdeanim.container import pack, unpack
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model.metrics import error_summary
from pdeanim.poses import make_poses


def strict_json(text: str) -> object:
    def refuse(name: str) -> None:
        raise ValueError(f"non-finite constant {name} in JSON")

    return json.loads(text, parse_constant=refuse)


def test_undefined_kg_is_null():
    v = np.zeros((4, 2, 3))
    summary = error_summary(v, v + 1e-3)
    assert summary["kg"] is None and math.isfinite(summary["rms"])


def test_one_vertex_clip_header_is_strict_json():
    """The 1-vertex clip of the audit: its header and report serialise without Infinity."""
    v = np.random.default_rng(0).normal(size=(5, 1, 3)).astype(np.float32)
    parts = fit_poses(make_poses(v, None), FitOptions())
    header, _ = unpack(parts.coefficients)
    strict_json(json.dumps(header))
    assert header["errors"]["kg"] is None
    assert parts.report["kg"] is None


@pytest.mark.parametrize("bad", [float("inf"), float("-inf"), float("nan")])
def test_pack_refuses_non_finite_header(bad):
    with pytest.raises(ValueError, match="NaN or infinity"):
        pack({"part": "x", "errors": {"kg": bad}}, {})
