"""The JS client plays a clip on GLBs that pdeanim writes, loaded by three.js's GLTFLoader: a frame GLB and
a quantised, meshopt-compressed animation GLB of an asset with several nodes, primitives and materials.
``attachClipToScene`` must put every vertex where the Python evaluator puts it and keep the materials."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pdeanim.clip import load_clip, write_clip_file
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.gltf.clipexport import clip_animation_glb, clip_frame_glb
from pdeanim.gltf.layout import gltf_layout
from pdeanim.gltf.read import read_animated_poses, read_static_mesh
from pdeanim.poses import make_poses
from tests.ci import missing
from tests.gltf.builders import textured_scene_glb

JS = Path(__file__).resolve().parents[2] / "clients" / "js"
SCRIPT = JS / "test" / "tools" / "gltf_attach.mjs"
NODE = shutil.which("node")
TIMES = [0.0, 0.35, 1.0]


@pytest.fixture(scope="module", autouse=True)
def node_tools() -> None:
    """node and clients/js/node_modules: a skip on a developer's machine without them, a failure under CI."""
    if NODE is None or not (JS / "node_modules" / "three").is_dir():
        missing("node and clients/js/node_modules (npm ci, run by script/setup) are needed")


@pytest.fixture(scope="module")
def asset(tmp_path_factory):
    """A textured 4-primitive scene, a clip fitted to a wave over it, and its frame and animation GLBs."""
    out = tmp_path_factory.mktemp("gltf-attach")
    src = textured_scene_glb()
    rest, faces = read_static_mesh(src)
    phase = np.arange(9)[:, None, None]
    frames = rest[None] + 0.05 * np.sin(rest[None, :, :1] * 3 + 0.7 * phase) * np.array([0.0, 1.0, 0.5])
    parts = fit_poses(make_poses(frames.astype(np.float32), faces), FitOptions(segments=2))
    write_clip_file(out / "asset.clip", parts)
    clip = load_clip(parts.topology, parts.coefficients)
    layout = gltf_layout(src)
    (out / "frame.glb").write_bytes(clip_frame_glb(clip, 0.6, layout))
    (out / "animation.glb").write_bytes(clip_animation_glb(clip, 8.0, layout=layout))
    return out, clip


def _run(glb: Path, clip: Path) -> dict:
    proc = subprocess.run([NODE, str(SCRIPT), str(glb), str(clip), ",".join(map(str, TIMES))],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.mark.parametrize("glb", ["frame.glb", "animation.glb"])
def test_attach_to_gltfloader_scene_matches_python(asset, glb):
    out, clip = asset
    res = _run(out / glb, out / "asset.clip")
    assert [m["name"] for m in res["meshes"]] and len(res["meshes"]) == 4  # 2 + 1 + 1 primitives
    assert {n for m in res["meshes"] for n in m["materials"]} == {"skin", "cloth"}
    assert res["materialsWhilePlaying"] == [m["materials"] for m in res["meshes"]]
    assert all("uv" in m["attributes"] for m in res["meshes"])
    # the clip's vertex replaces the morphed one (mixed by the player's influence, 1 here): the GLB's morph
    # targets need not be switched off, and are left as they are
    assert res["influenceWhilePlaying"] == 1
    assert res["morphWhilePlaying"] == res["morphBefore"]
    assert res["morphAfter"] == res["morphBefore"]
    if glb == "animation.glb":
        assert any(res["morphBefore"])
    shown = [v for m in res["vertexMaps"] for v in m]  # the clip vertex of each written vertex
    # nothing merged: every clip vertex written once (an animation GLB in fetch order, a frame GLB in order)
    assert sorted(shown) == list(range(clip.n_vertices))
    if glb == "frame.glb":
        assert shown == list(range(clip.n_vertices))
    want = clip.evaluate(np.asarray(TIMES))[:, shown]
    diag = float(np.linalg.norm(np.ptp(want[0], axis=0)))
    got = np.asarray(res["frames"])
    assert got.shape == want.shape
    # float32 local coordinates through the nodes' transforms: 1e-6 of the diagonal is ~10x the rounding
    assert np.abs(got - want).max() <= 1e-6 * diag


def test_attach_to_a_welded_glb_plays_every_vertex_through_its_map(tmp_path):
    """The Fox (1,728 unwelded corners) exports as 434 welded vertices with a _PDEANIM_VERTEX map
    (docs/gltf.md): attachClipToScene takes it as the vertex map, so each written vertex shows its clip
    vertex."""
    src = (Path(__file__).resolve().parents[1] / "gltf" / "data" / "Fox.glb").read_bytes()
    poses = read_animated_poses(src, fps=30, animation="Run")
    parts = fit_poses(make_poses(poses.vertices[:8].astype(np.float32), poses.faces), FitOptions(segments=2))
    write_clip_file(tmp_path / "fox.clip", parts)
    clip = load_clip(parts.topology, parts.coefficients)
    (tmp_path / "fox.glb").write_bytes(clip_animation_glb(clip, 8.0, layout=gltf_layout(src)))
    res = _run(tmp_path / "fox.glb", tmp_path / "fox.clip")
    (vertex_map,) = res["vertexMaps"]
    assert len(vertex_map) == 434 < clip.n_vertices == 1728
    want = clip.evaluate(np.asarray(TIMES))[:, vertex_map]
    diag = float(np.linalg.norm(np.ptp(want[0], axis=0)))
    assert np.abs(np.asarray(res["frames"]) - want).max() <= 1e-6 * diag
