"""The upload validator's child process (pdeanim_service.api.validator), called directly: results come back,
input
errors keep their status and message, and its memory and time limits answer 413 naming their settings."""

from __future__ import annotations

from pathlib import Path

import pytest

from pdeanim_service.api.errors import ApiError
from pdeanim_service.api.validator import run_checked
from pdeanim_service.settings import Settings

from . import bombs


def _mesh(tmp_path: Path, name: str, data: bytes, **settings) -> dict:
    """run_checked("mesh_stats") on ``data`` saved as ``name``, with ``settings`` overridden."""
    path = tmp_path / name
    path.write_bytes(data)
    config = Settings(data_dir=tmp_path / "data", **settings)
    return run_checked("mesh_stats", (str(path), name, config.model_dump_json()), config)


def test_stats_and_input_errors_come_back(tmp_path) -> None:
    assert _mesh(tmp_path, "t.glb", bombs.pack_glb(*bombs._tetra_doc()))["vertices"] == 4
    with pytest.raises(ApiError) as info:
        _mesh(tmp_path, "n.glb", bombs.node_flood(11), max_gltf_nodes=10)
    assert info.value.status_code == 413 and info.value.code == "limit_exceeded"
    assert "PDEANIM_MAX_GLTF_NODES" in info.value.detail


def test_memory_budget_is_a_413_naming_it(tmp_path) -> None:
    """A 400,000-vertex accessor of zeros is 9.6 MB of float64: over a 1 MiB address-space budget."""
    doc, raw = bombs._tetra_doc()
    doc["accessors"].append({"componentType": 5126, "count": 400_000, "type": "VEC3"})
    doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": 2}]
    doc["accessors"][0]["count"] = 4
    with pytest.raises(ApiError) as info:
        _mesh(tmp_path, "m.glb", bombs.pack_glb(doc, raw), upload_memory_bytes=1024 * 1024)
    assert info.value.status_code == 413 and "PDEANIM_UPLOAD_MEMORY_BYTES" in info.value.detail


def test_time_limit_is_a_413_naming_it(tmp_path) -> None:
    """The 200k-primitive flood takes about half a second of CPU to refuse: over a 50 ms limit."""
    with pytest.raises(ApiError) as info:
        _mesh(tmp_path, "p.glb", bombs.primitive_flood(200_000), upload_timeout_seconds=0.05)
    assert info.value.status_code == 413 and "PDEANIM_UPLOAD_TIMEOUT_SECONDS" in info.value.detail
