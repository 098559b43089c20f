"""three.js reads what pdeanim writes: GLTFLoader with MeshoptDecoder (npm ``three``, tools/three-gltf-check,
installed by script/setup) loads a compact animation GLB and a look-keeping one in node, with the morph
targets, normals, UVs, materials and texture a three.js app would get."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pdeanim.gltf.compact import layout_animation_glb
from pdeanim.gltf.layout import gltf_layout, plain_layout
from pdeanim.gltf.read import read_static_mesh
from tests.ci import missing

from .builders import textured_scene_glb

TOOL = Path(__file__).resolve().parents[2] / "tools" / "three-gltf-check"


def load_in_three(tmp_path: Path, glbs: dict[str, bytes]) -> dict[str, dict]:
    """What three.js's GLTFLoader makes of each GLB (see tools/three-gltf-check/check.mjs)."""
    node = shutil.which("node")
    if node is None or not (TOOL / "node_modules" / "three").is_dir():
        missing("node or tools/three-gltf-check/node_modules is missing: run script/setup")  # fails under CI
    paths = []
    for name, data in glbs.items():
        paths.append(tmp_path / f"{name}.glb")
        paths[-1].write_bytes(data)
    run = subprocess.run([node, str(TOOL / "check.mjs"), *map(str, paths)], capture_output=True, text=True,
                         timeout=120)
    lines = [json.loads(line) for line in run.stdout.splitlines() if line.strip()]
    assert run.returncode == 0, run.stdout + run.stderr
    return {Path(r["file"]).stem: r for r in lines}


def test_three_loads_compact_and_look_keeping_animations(tmp_path, morph):
    frames, faces, times = morph
    k = 12
    key_times = (times[:k] - times[0]).astype(np.float32)
    plain = layout_animation_glb(plain_layout(faces, frames.shape[1]), frames[:k], key_times, np.arange(k), k)
    src = textured_scene_glb()
    rest, _ = read_static_mesh(src)
    wave = rest[None] + 0.05 * np.arange(4)[:, None, None] * np.sin(rest[None, :, :1])
    look = layout_animation_glb(gltf_layout(src), wave, np.arange(4, dtype=np.float32), np.arange(4), 4)
    got = load_in_three(tmp_path, {"plain": plain, "look": look})
    (mesh,) = got["plain"]["meshes"]
    assert mesh["vertices"] == frames.shape[1] and mesh["positionType"] == "Int16Array"
    assert mesh["targets"] == mesh["normalTargets"] == mesh["influences"] == k and mesh["relative"]
    assert got["plain"]["animations"][0]["tracks"] == 1
    duration = got["plain"]["animations"][0]["duration"]
    assert duration == pytest.approx(float(times[k - 1] - times[0]), rel=1e-5)
    meshes = got["look"]["meshes"]
    assert [m["material"] for m in meshes] == ["skin", "cloth", "cloth", "cloth"]
    assert [m["map"] for m in meshes] == ["checker", None, None, None]
    assert all(m["uv"] and m["normal"] and m["targets"] == 4 for m in meshes)
    assert [m["parent"] for m in meshes[::2]] == ["body_mesh", "hat"]  # named nodes kept above the meshes
    assert got["look"]["animations"][0]["tracks"] == 4  # one per three.js Mesh (body has 2 primitives)
