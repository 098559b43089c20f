"""Animation exports of clips with a bone layer (format 1.1): a skinned glTF animation (plus morph targets of
a non-zero residual) that the Khronos validator accepts and three.js's AnimationMixer plays as the clip."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pdeanim.clip import load_clip_file
from pdeanim.gltf.clipexport import clip_animation_glb, clip_duration, export_times
from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.skinexport import residual_is_zero
from pdeanim.gltf.validate import assert_clean, validate_many
from tests.ci import missing

FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"
TOOL = Path(__file__).resolve().parents[2] / "tools" / "three-gltf-check"
CASES = ["bones-fit-k2-zero", "bones-fit-k4-residual", "bones-synthetic-k3-zero-loop",
         "bones-synthetic-k2-residual"]
FPS = 12.0


@pytest.fixture(scope="module")
def exports() -> dict[str, tuple[object, bytes]]:
    return {name: (clip, clip_animation_glb(clip, FPS)) for name in CASES
            for clip in [load_clip_file(FIXTURES / f"{name}.clip")]}


def test_exports_are_skinned_and_validator_clean(exports):
    reports = validate_many([glb for _, glb in exports.values()])
    for (name, (clip, glb)), report in zip(exports.items(), reports, strict=True):
        assert_clean(report, name)
        doc, _ = unpack_glb(glb)
        (skin,) = doc["skins"]
        B = clip.coef.bones.n_bones
        assert len(skin["joints"]) == B and "inverseBindMatrices" in skin
        prim = doc["meshes"][0]["primitives"][0]
        assert {"JOINTS_0", "WEIGHTS_0", "POSITION"} <= set(prim["attributes"])
        paths = [c["target"]["path"] for c in doc["animations"][0]["channels"]]
        assert paths.count("translation") == paths.count("rotation") == B
        zero = residual_is_zero(clip)
        assert zero == name.endswith(("zero", "zero-loop"))
        assert ("targets" in prim) == (not zero) and ("weights" in paths) == (not zero)


def test_three_mixer_plays_the_clip_at_the_keys(tmp_path, exports):
    """At every key three.js (skinning on the CPU, morph targets first) shows the clip's positions."""
    node = shutil.which("node")
    if node is None or not (TOOL / "node_modules" / "three").is_dir():
        missing("node or tools/three-gltf-check/node_modules is missing: run script/setup")
    for name, (clip, glb) in exports.items():
        path = tmp_path / f"{name}.glb"
        path.write_bytes(glb)
        duration = clip_duration(clip)
        seconds = export_times(duration, FPS)
        keys = [float(np.float32(s)) for s in seconds[:-1]]  # the mixer wraps exactly at the duration
        run = subprocess.run([node, str(TOOL / "mixer.mjs"), str(path), ",".join(map(repr, keys))],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        (mesh,) = json.loads(run.stdout)["meshes"]
        got = np.asarray(mesh["frames"]).reshape(len(keys), -1, 3)
        want = np.asarray(clip.evaluate(np.asarray(seconds[:-1]) / duration), np.float64)
        diag = float(np.linalg.norm(np.ptp(want[0], axis=0)))
        # float32 joints, quaternions and bind-pose targets, summed in float32 by three.js: 3.3e-8 to 5.0e-8
        # of the diagonal measured (2026-12-07)
        assert np.abs(got - want).max() <= 1.5e-7 * diag, name


def test_a_source_look_keeps_the_morph_target_export(exports):
    """With a source's look (here an OBJ's UVs) the frames are baked into morph targets as for any clip (the
    look-keeping writer has no joints): a clip with bones still exports, validator-clean."""
    from pdeanim.gltf.layout import plain_layout

    clip, _ = exports["bones-fit-k2-zero"]
    plain = plain_layout(clip.faces, clip.n_vertices)
    skinned = clip_animation_glb(clip, FPS, layout=plain)
    assert "skins" in unpack_glb(skinned)[0]
    look = plain_layout(clip.faces, clip.n_vertices, uv=np.zeros((clip.n_vertices, 2)))
    baked = clip_animation_glb(clip, FPS, layout=look)
    doc, _ = unpack_glb(baked)
    assert "skins" not in doc and doc["meshes"][0]["primitives"][0]["targets"]
    assert_clean(validate_many([baked])[0], "baked bones export")


def test_cli_export_of_a_clip_with_bones_says_it_is_skinned(tmp_path, capsys):
    from pdeanim_service.cli import main

    out = tmp_path / "bones.glb"
    assert main(["export", str(FIXTURES / "bones-fit-k2-zero.clip"), "--out", str(out), "--fps", "24",
                 "-q"]) == 0
    assert "skinned, 3 joints, float32" in capsys.readouterr().out
    doc, _ = unpack_glb(out.read_bytes())
    assert len(doc["skins"][0]["joints"]) == 3 and "targets" not in doc["meshes"][0]["primitives"][0]
