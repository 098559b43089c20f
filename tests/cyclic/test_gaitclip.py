"""Gait output: the looping fitted clip (travel speed in its header and info, planted feet measured on the
clip itself), the looping GLB that keeps the model's look, and the header rewrite they use."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.container import with_header
from pdeanim.cyclic.gaitclip import fit_gait_clip, gait_glb, solve_gait
from pdeanim.cyclic.gaits import GaitParams
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.errors import InputError, ParameterError
from pdeanim.gltf.read import read_animated_poses
from pdeanim.gltf.validate import assert_glb_clean
from pdeanim.mesh.io import load_mesh
from tests.gltf.builders import clip_vertices

from .rig import QUADRUPED, rig_glb


@pytest.fixture(scope="module")
def trot():
    return solve_gait(rig_glb(QUADRUPED), GaitParams.preset("trot"), frames=16)


@pytest.fixture(scope="module")
def trot_clip(trot):
    return fit_gait_clip(trot, 1e-3)


def test_clip_loops_and_carries_the_travel_speed(trot, trot_clip):
    clip = load_clip(trot_clip.topology, trot_clip.coefficients)
    assert clip.looping and np.array_equal(clip.evaluate(0.0), clip.evaluate(1.0))
    header, _ = container.unpack(trot_clip.coefficients)
    speed = trot.cycle.speed
    assert header["travel"]["speed"] == pytest.approx(speed)
    assert header["travel"]["direction"] == [0.0, 0.0, 1.0]
    assert header["travel"]["distance_per_cycle"] == pytest.approx(speed / 1.8)
    assert clip.info()["travel"] == header["travel"] and clip.info()["gait"]["name"] == "trot"
    assert [leg["phase"] for leg in header["gait"]["legs"]] == [0.0, 0.5, 0.5, 0.0]
    r = trot_clip.report
    assert r["rel_rms"] <= 1e-3 and r["travel"]["speed"] == pytest.approx(speed)
    # the fit adds its error to the planted feet: measured 0.32% of the leg (slide, every sole vertex in every
    # frame it is down) and 6e-10 (height) at rel RMS 1e-3 (achieved 5.1e-4); allowed 2-3x
    assert r["contact_clip"]["slide_max_rel"] < 8e-3 and r["contact_clip"]["stance_height_max_rel"] < 1e-3
    assert r["contact"]["slide_max_rel"] < 1e-6


def test_with_header_keeps_the_arrays(trot_clip):
    before_h, before_a = container.unpack(trot_clip.coefficients)
    blob = with_header(trot_clip.coefficients, {"extra": {"a": 1}})
    after_h, after_a = container.unpack(blob)
    assert after_h == {**before_h, "extra": {"a": 1}}
    assert all(np.array_equal(after_a[k], before_a[k]) for k in before_a)


def test_glb_keeps_the_fox_look_and_loops(data_dir):
    fox = data_dir / "Fox.glb"
    result = solve_gait(fox, GaitParams.preset("gallop"), frames=12)
    glb = gait_glb(fox, result)
    assert_glb_clean(glb, "fox gallop")
    n = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20:20 + n])
    assert doc["materials"][0]["name"] == "fox_material" and doc["images"][0]["mimeType"] == "image/png"
    assert "TEXCOORD_0" in doc["meshes"][0]["primitives"][0]["attributes"]
    assert doc["animations"][0]["extras"]["loop"] is True
    back = read_animated_poses(glb, fps=12 / result.cycle.params.period)
    shown = clip_vertices(glb)  # the Fox is flat-shaded: its corners weld (1,728 -> 434 with its UVs)
    assert back.vertices.shape == (len(result.poses.vertices), len(shown), 3) and len(shown) < 1728
    diag = np.linalg.norm(np.ptp(result.poses.vertices[0], axis=0))
    assert np.abs(back.vertices - result.poses.vertices[:, shown]).max() < 1e-3 * diag  # 14-bit positions
    assert np.abs(back.vertices[-1] - back.vertices[0]).max() == 0.0
    contact = result.report["contact"]  # paws skinned partly to the bones above: measured 0.35%, 0.29%
    assert contact["slide_max_rel"] < 0.01 and contact["stance_height_max_rel"] < 0.01


def test_the_job_options_and_dispatch(tmp_path):
    opts = CyclicOptions.from_dict({"mode": "pace", "frames": 8, "overrides": {"step_length": 0.2},
                                    "legs": ["front.L.2", "front.R.2", "hind.L.3", "hind.R.3"],
                                    "forward": [0, 0, 1], "target_rel_rms": 2e-3})
    assert opts.is_gait and CyclicOptions.from_dict(opts.to_dict()) == opts
    for bad in ({"mode": "trot", "amplitude": 0.1}, {"mode": "trot", "legs": "paw"},
                {"mode": "trot", "frames": 5000}, {"mode": "trot", "target_rel_rms": 0.0},
                {"mode": "trot", "forward": [1, 2]}):
        with pytest.raises(ParameterError):
            CyclicOptions.from_dict(bad)
    path = tmp_path / "quad.glb"
    path.write_bytes(rig_glb(QUADRUPED))
    mesh = load_mesh(path)
    with pytest.raises(ParameterError, match="skinned glTF"):
        make_cyclic_clip(mesh, opts)
    parts = make_cyclic_clip(mesh, opts, source=path.read_bytes())
    assert parts.report["gait"]["name"] == "pace" and parts.report["options"]["legs"] == opts.legs
    assert load_clip(parts.topology, parts.coefficients).n_vertices == len(mesh.vertices)
    with pytest.raises(InputError):
        make_cyclic_clip(mesh, CyclicOptions(mode="trot"), source=b"v 0 0 0\n")
