"""Animation exports through real HTTP (a real ``pdeanim serve`` and ``pdeanim worker``): a clip of an
uploaded textured glTF keeps its look in frame and animation GLBs; the animation is quantised and
meshopt-compressed; fps above PDEANIM_MAX_EXPORT_FPS is a 422; an export above
PDEANIM_MAX_SYNC_EXPORT_BYTES is refused by the route (413 naming the job to submit) and built by an
``export`` job instead, downloadable from its result."""

from __future__ import annotations

import io

import numpy as np
import pytest

from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.read import read_animated_poses, read_static_mesh
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Job

from ..gltf.builders import clip_vertices, textured_scene_glb
from .conftest import running_services
from .harness import wait_job

POSTGRES_NIGHTLY = True  # routes over the store: CI runs them on SQLite (conftest)

FRAMES = 10  # poses at 30 fps: 0.3 s
VERTICES = 43  # of textured_scene_glb
MAX_FPS = 60
# 30 fps: 10 frames x 43 vertices x 12 = 5160 bytes (built in the request); 60 fps: 19 frames, 9804 (a job)
SYNC_BYTES = 8_000


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"),
                                {"PDEANIM_MAX_EXPORT_FPS": str(MAX_FPS),
                              "PDEANIM_MAX_SYNC_EXPORT_BYTES": str(SYNC_BYTES)})


def upload(api, name: str, data: bytes, path: str = "/v1/meshes"):
    return api.post(path, files={"file": (name, data, "application/octet-stream")})


def assert_error(r, status: int, code: str) -> str:
    assert r.status_code == status, r.text
    assert r.json()["error"]["code"] == code, r.json()
    return r.json()["error"]["message"]


@pytest.fixture(scope="module")
def scene(api, services) -> dict:
    """The textured scene uploaded as a mesh, waving poses of it, and the fitted clip."""
    src = textured_scene_glb()
    mesh = upload(api, "scene.glb", src)
    assert mesh.status_code == 201, mesh.text
    assert mesh.json()["vertices"] == VERTICES
    rest, _ = read_static_mesh(src)
    phase = np.arange(FRAMES)[:, None, None] / FRAMES
    frames = rest[None] + 0.1 * np.sin(2 * np.pi * phase + rest[None, :, :1])
    buf = io.BytesIO()
    np.savez(buf, vertices=frames.astype(np.float32))
    poses = upload(api, "wave.npz", buf.getvalue(), f"/v1/meshes/{mesh.json()['id']}/poses")
    assert poses.status_code == 201, poses.text
    r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses.json()["id"], "params": {"segments": 1}})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"], timeout=240)
    assert job["state"] == "succeeded", (job, services.logs())
    return {"src": src, "mesh": mesh.json(), "clip_id": job["result"]["clip_id"], "frames": frames}


def check_look(glb: bytes, src: bytes) -> dict:
    doc, _ = unpack_glb(glb)
    sdoc, _ = unpack_glb(src)
    assert all(doc[k] == sdoc[k] for k in ("materials", "textures", "samplers"))
    assert [n.get("name") for n in doc["nodes"][:3]] == ["body", "hat", "wing"]
    assert [len(m["primitives"]) for m in doc["meshes"]] == [2, 1, 1]
    assert all("TEXCOORD_0" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
    return doc


def test_frame_and_animation_keep_the_look(api, scene):
    cid = scene["clip_id"]
    frame = api.get(f"/v1/clips/{cid}/frame", params={"t": 0.5})
    assert frame.status_code == 200, frame.text
    check_look(frame.content, scene["src"])
    anim = api.get(f"/v1/clips/{cid}/animation", params={"fps": 30})
    assert anim.status_code == 200, anim.text
    doc = check_look(anim.content, scene["src"])
    assert doc["extensionsRequired"] == ["KHR_mesh_quantization", "EXT_meshopt_compression"]
    poses = read_animated_poses(anim.content, fps=30)  # decodes meshopt
    assert poses.n_frames == FRAMES
    diag = float(np.linalg.norm(np.ptp(scene["frames"][0], axis=0)))
    shown = clip_vertices(anim.content)  # primitives in fetch order, through their _PDEANIM_VERTEX maps
    assert np.abs(poses.vertices - scene["frames"][:, shown]).max() < 0.05 * diag  # a 1-segment fit
    reports = validate_many([frame.content, anim.content])
    for label, report in zip(["frame", "animation"], reports, strict=True):
        assert_clean(report, label)


def test_fps_is_bounded_by_the_setting(api, scene):
    cid = scene["clip_id"]
    too_fast = api.get(f"/v1/clips/{cid}/animation", params={"fps": MAX_FPS + 1})
    msg = assert_error(too_fast, 422, "fps_out_of_range")
    assert "PDEANIM_MAX_EXPORT_FPS" in msg
    assert api.get(f"/v1/clips/{cid}/animation", params={"fps": 0}).status_code == 422
    job = api.post("/v1/jobs", json={"kind": "export", "clip_id": cid, "fps": 1000})
    assert_error(job, 422, "fps_out_of_range")


def test_large_export_is_a_job_with_a_downloadable_glb(api, other, scene, services):
    cid = scene["clip_id"]
    big = api.get(f"/v1/clips/{cid}/animation", params={"fps": MAX_FPS})
    msg = assert_error(big, 413, "export_too_large")
    assert '"kind": "export"' in msg and cid in msg and "PDEANIM_MAX_SYNC_EXPORT_BYTES" in msg
    r = api.post("/v1/jobs", json={"kind": "export", "clip_id": cid, "fps": MAX_FPS})
    assert r.status_code == 202, r.text
    assert r.json()["mesh_id"] == scene["mesh"]["id"] and r.json()["params"]["params"]["fps"] == MAX_FPS
    job = wait_job(api, r.json()["id"])
    assert job["state"] == "succeeded", (job, services.logs())
    url = job["result"]["export_url"]
    assert url == f"/v1/exports/{job['id']}"
    glb = api.get(url)
    assert glb.status_code == 200 and glb.headers["content-type"] == "model/gltf-binary"
    assert len(glb.content) == job["result"]["export_bytes"]
    assert glb.headers["content-encoding"] == "zstd"  # httpx with zstandard accepts it; decoded above
    for accept, coding in (("gzip", "gzip"), ("identity", None)):
        again = api.get(url, headers={"Accept-Encoding": accept})
        assert again.headers.get("content-encoding") == coding and again.content == glb.content
    check_look(glb.content, scene["src"])
    assert read_animated_poses(glb.content, fps=MAX_FPS).n_frames == 19  # 0.3 s at 60 fps, both ends
    assert_clean(validate_many([glb.content])[0], "export job GLB")
    assert_error(other.get(url), 404, "not_found")  # another tenant's job


def test_export_job_requests_are_checked(api, scene):
    cid = scene["clip_id"]
    assert_error(api.post("/v1/jobs", json={"kind": "export"}), 422, "invalid_parameter")
    missing = api.post("/v1/jobs", json={"kind": "export", "clip_id": "clip_nope"})
    assert_error(missing, 404, "not_found")
    bogus = api.post("/v1/jobs", json={"kind": "export", "clip_id": cid, "bogus": 1})
    assert_error(bogus, 422, "invalid_parameter")
    assert_error(api.post("/v1/jobs", json={"kind": "export", "clip_id": cid, "position_bits": 20}), 422,
                 "invalid_parameter")
    assert_error(api.post("/v1/jobs", json={"kind": "fit", "clip_id": cid}), 422, "invalid_parameter")
    fit_job = api.get(f"/v1/clips/{cid}").json()["job_id"]
    assert_error(api.get(f"/v1/exports/{fit_job}"), 404, "not_found")  # not an export job
    queued = api.post("/v1/jobs", json={"kind": "export", "clip_id": cid, "fps": 5}).json()
    r = api.get(f"/v1/exports/{queued['id']}")
    assert r.status_code in (200, 409)  # 409 not_ready until the worker is done
    assert wait_job(api, queued["id"])["state"] == "succeeded"
    assert api.get(f"/v1/exports/{queued['id']}").status_code == 200


@pytest.fixture(scope="module")
def store(services):
    st = Store.open(services.backend.settings())
    yield st
    st.close()


def fitted_clip(api, services, mesh: dict, frames: np.ndarray) -> str:
    """Upload ``frames`` as poses of ``mesh``, fit them with one segment; the clip id."""
    buf = io.BytesIO()
    np.savez(buf, vertices=frames.astype(np.float32))
    poses = upload(api, "wave.npz", buf.getvalue(), f"/v1/meshes/{mesh['id']}/poses")
    assert poses.status_code == 201, poses.text
    r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses.json()["id"], "params": {"segments": 1}})
    job = wait_job(api, r.json()["id"], timeout=240)
    assert job["state"] == "succeeded", (job, services.logs())
    return job["result"]["clip_id"]


def exported(api, services, store: Store, clip_id: str, fps: int) -> tuple[dict, str]:
    """A succeeded export job of ``clip_id`` at ``fps`` and the blob key of its GLB (present)."""
    r = api.post("/v1/jobs", json={"kind": "export", "clip_id": clip_id, "fps": fps})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"])
    assert job["state"] == "succeeded", (job, services.logs())
    assert api.get(f"/v1/exports/{job['id']}").status_code == 200
    with store.sessions() as session:
        key = session.get(Job, job["id"]).result["export_key"]
    assert store.blobs.exists(key)
    return job, key


def test_exports_go_with_their_clip_and_their_mesh(api, scene, services, store):
    # poses and fps no other test uses: blobs are content-addressed, so a shared GLB would rightly be kept
    clip_id = fitted_clip(api, services, scene["mesh"], scene["frames"] * 1.01)
    job, key = exported(api, services, store, clip_id, 7)
    listed = api.get("/v1/jobs", params={"kind": "export", "mesh_id": scene["mesh"]["id"]})
    assert listed.status_code == 200 and job["id"] in {j["id"] for j in listed.json()["items"]}, listed.text
    r = api.delete(f"/v1/clips/{clip_id}")
    assert r.status_code == 200 and r.json()["clips"] == 1 and r.json()["jobs"] == 1, r.text
    assert_error(api.get(f"/v1/exports/{job['id']}"), 404, "not_found")
    assert api.get(f"/v1/jobs/{job['id']}").status_code == 404
    assert not store.blobs.exists(key)
    assert api.get(f"/v1/clips/{scene['clip_id']}").status_code == 200  # the other clip stays

    mesh = upload(api, "scene.glb", scene["src"]).json()  # the same file: one shared mesh blob
    clip_id = fitted_clip(api, services, mesh, scene["frames"] * 0.99)
    job, key = exported(api, services, store, clip_id, 11)
    r = api.delete(f"/v1/meshes/{mesh['id']}")
    assert r.status_code == 200 and r.json()["jobs"] == 2, r.text  # the fit and the export
    assert_error(api.get(f"/v1/exports/{job['id']}"), 404, "not_found")
    assert not store.blobs.exists(key)
    assert api.get(f"/v1/meshes/{scene['mesh']['id']}").status_code == 200


def test_encoded_download_304_carries_the_weak_etag_of_its_200(api, scene, services):
    r = api.post("/v1/jobs", json={"kind": "export", "clip_id": scene["clip_id"], "fps": 5})
    url = f"/v1/exports/{wait_job(api, r.json()['id'])['id']}"
    for coding in ("zstd", "gzip"):
        first = api.get(url, headers={"Accept-Encoding": coding})
        assert first.status_code == 200 and first.headers["content-encoding"] == coding
        etag = first.headers["etag"]
        assert etag.startswith('W/"')
        again = api.get(url, headers={"Accept-Encoding": coding, "If-None-Match": etag})
        assert again.status_code == 304 and again.headers["etag"] == etag, again.headers
        assert again.headers["vary"] == "Accept-Encoding"
    plain = api.get(url, headers={"Accept-Encoding": "identity"})
    assert not plain.headers["etag"].startswith("W/")
    strong = api.get(url, headers={"Accept-Encoding": "identity", "If-None-Match": plain.headers["etag"]})
    assert strong.status_code == 304 and strong.headers["etag"] == plain.headers["etag"]
    head = api.head(url, headers={"Accept-Encoding": "zstd"})
    assert head.status_code == 200 and head.content == b"" and head.headers["etag"] == etag
