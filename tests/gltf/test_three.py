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

from .builders import clip_vertices, textured_scene_glb

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
    assert mesh["vertices"] == len(clip_vertices(plain)) and mesh["positionType"] == "Int16Array"
    assert mesh["targets"] == mesh["normalTargets"] == mesh["influences"] == k and mesh["relative"]
    assert got["plain"]["animations"][0]["tracks"] == 1
    duration = got["plain"]["animations"][0]["duration"]
    assert duration == pytest.approx(float(times[k - 1] - times[0]), rel=1e-5)
    meshes = got["look"]["meshes"]
    assert [m["material"] for m in meshes] == ["skin", "cloth", "cloth", "cloth"]
    assert [m["map"] for m in meshes] == ["checker", None, None, None]
    assert all(m["uv"] and m["targets"] == 4 for m in meshes)
    # the hat's source has no normals: written without, three.js shades it flat as it shades the source
    assert [(m["normal"], m["flatShading"]) for m in meshes] == [(True, False)] * 2 + [(False, True)] * 2
    assert [m["parent"] for m in meshes[::2]] == ["body_mesh", "hat"]  # named nodes kept above the meshes
    assert got["look"]["animations"][0]["tracks"] == 4  # one per three.js Mesh (body has 2 primitives)


def test_mixer_plays_a_welded_animation_as_the_frames(tmp_path):
    """three.js's AnimationMixer plays the welded, look-keeping animation of the flat-shaded Fox (1,728
    corners written as 434 vertices): at each key every vertex is where its clip vertex is (through the
    ``_PDEANIM_VERTEX`` map), between keys on the line between the two frames."""
    from pdeanim.gltf.read import read_animated_poses

    src = (Path(__file__).parent / "data" / "Fox.glb").read_bytes()
    frames = read_animated_poses(src, fps=30, animation="Run").vertices[:8].astype(np.float32)
    k = len(frames)
    glb = layout_animation_glb(gltf_layout(src), frames, np.arange(k, dtype=np.float32) / 30, np.arange(k), k)
    path = tmp_path / "fox.glb"
    path.write_bytes(glb)
    node = shutil.which("node")
    if node is None or not (TOOL / "node_modules" / "three").is_dir():
        missing("node or tools/three-gltf-check/node_modules is missing: run script/setup")
    times = [i / 30 for i in range(k)] + [2.5 / 30]
    run = subprocess.run([node, str(TOOL / "mixer.mjs"), str(path), ",".join(map(str, times))],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    (mesh,) = json.loads(run.stdout)["meshes"]
    clip_vertex = np.asarray(mesh["map"], np.int64)
    assert len(clip_vertex) == 434 and sorted(set(clip_vertex)) == sorted(clip_vertex)
    got = np.asarray(mesh["frames"]).reshape(len(times), -1, 3)
    want = np.concatenate([frames, 0.5 * (frames[2:3] + frames[3:4])])[:, clip_vertex]
    step = float(np.ptp(frames.reshape(-1, 3), axis=0).max()) / (2**14 - 1)
    # base and delta each round to half a 14-bit step, three.js sums in float32: 2x margin on one step
    assert np.abs(got - want).max() <= 2 * step
    # every clip vertex is shown: the unwelded corners are copies of the welded vertices
    rows = np.unique(frames.transpose(1, 0, 2).reshape(len(frames[0]), -1), axis=0, return_inverse=True)[1]
    assert set(rows.reshape(-1)[clip_vertex]) == set(rows.reshape(-1))
