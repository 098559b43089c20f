"""Reads bounded by what they return, through a real server whose clip cache is too small for any clip
(``PDEANIM_CLIP_CACHE_BYTES=1``): the metadata comes from the parts' headers, and frames and animations of a
clip too large to decode whole are evaluated a block of curves at a time; every answer is byte-identical to
what the library computes from the fully decoded clip."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from pdeanim.clip import load_clip
from pdeanim.gltf.clipexport import clip_animation_glb
from pdeanim.gltf.layout import source_layout
from pdeanim.gltf.write import FrameGlb
from pdeanim.poses import make_poses, poses_to_bytes

from .conftest import running_services
from .harness import wait_job

pytestmark = pytest.mark.slow  # a server, a worker and a fit: about a minute on a loaded machine


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"),
                                {"PDEANIM_CLIP_CACHE_BYTES": "1"}, server_args=("--workers", "1"))


@pytest.fixture(scope="module")
def scene(api) -> dict:
    """A small fitted clip (an icosphere of 642 vertices, 24 frames of a travelling wave) and its mesh."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rest = np.asarray(sphere.vertices, np.float64)
    t = np.linspace(0.0, 1.0, 24)[:, None, None]
    frames = rest[None] + 0.1 * np.sin(4 * t + 2 * rest[None, :, [1, 2, 0]])
    poses = make_poses(frames.astype(np.float32), np.asarray(sphere.faces, np.int32))
    buf = io.StringIO()
    np.savetxt(buf, poses.vertices[0], fmt="v %.9g %.9g %.9g")
    np.savetxt(buf, poses.faces + 1, fmt="f %d %d %d")
    obj = buf.getvalue().encode()
    mesh = api.post("/v1/meshes", files={"file": ("sphere.obj", obj)})
    assert mesh.status_code == 201, mesh.text
    up = api.post(f"/v1/meshes/{mesh.json()['id']}/poses", files={"file": ("p.npz", poses_to_bytes(poses))})
    assert up.status_code == 201, up.text
    r = api.post("/v1/jobs", json={"kind": "fit", "mesh_id": mesh.json()["id"], "poses_id": up.json()["id"],
                                   "params": {"target_rel_rms": 3e-3}})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"])
    assert job["state"] == "succeeded", job
    clip_id = job["result"]["clip_id"]
    topology = api.get(f"/v1/clips/{clip_id}/topology").content
    coefficients = api.get(f"/v1/clips/{clip_id}/coefficients").content
    return {"id": clip_id, "clip": load_clip(topology, coefficients), "obj": obj}


def test_metadata_frames_and_animation_equal_the_decoded_clips(api, scene):
    clip, url = scene["clip"], f"/v1/clips/{scene['id']}"
    meta = api.get(url)
    assert meta.status_code == 200, meta.text
    info = clip.info()
    assert meta.json()["info"] == {**info, "errors": meta.json()["info"]["errors"]}
    assert meta.json()["frames"] == info["n_frames"] and meta.json()["segments"] == info["n_segments"]
    writer = FrameGlb(clip.faces, clip.n_vertices)
    for t in (0.0, 0.37, 1.0):
        r = api.get(f"{url}/frame", params={"t": t})
        assert r.status_code == 200, r.text
        assert r.content == writer(clip.evaluate(t))
    layout = source_layout(scene["obj"], "sphere.obj", clip.faces, clip.n_vertices)
    anim = api.get(f"{url}/animation", params={"fps": 12})
    assert anim.status_code == 200, anim.text
    assert anim.content == clip_animation_glb(clip, 12.0, layout=layout, max_frames=2000)
    assert api.get(f"{url}/frame", params={"t": 1.5}).status_code == 422  # checks unchanged
