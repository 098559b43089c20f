"""Every gait through the service: a real ``pdeanim serve`` and ``pdeanim worker`` (SQLite, local blobs),
the skinned rigs and the public Fox uploaded as GLB, cyclic jobs with a gait mode, the looping clips' travel
speed in their metadata, the animation GLB keeping the Fox's look, and clear failures."""

from __future__ import annotations

import json
import struct

import pytest

from pdeanim.gltf.validate import assert_glb_clean

from ..gltf.draco_builder import draco_glb
from ..service.conftest import Backend, running_services
from ..service.harness import client, make_key, wait_job
from .rig import BIPED, CONTROLLED, HEXAPOD, QUADRUPED, rig_glb
from .test_cli import GAIT_CASES

RIGS = {"biped": BIPED, "quadruped": QUADRUPED, "hexapod": HEXAPOD}


@pytest.fixture(scope="module")
def services(tmp_path_factory):
    backend = Backend("sqlite", {"PDEANIM_DATA_DIR": str(tmp_path_factory.mktemp("data"))})
    yield from running_services(backend, tmp_path_factory.mktemp("svc"))


@pytest.fixture(scope="module")
def api(services):
    with client(services, make_key(services.backend, "alice")) as c:
        yield c


def _upload(api, name: str, data: bytes) -> str:
    r = api.post("/v1/meshes", files={"file": (name, data, "model/gltf-binary")})
    assert r.status_code == 201, r.text
    return r.json()["id"]


@pytest.fixture(scope="module")
def meshes(api, data_dir) -> dict[str, str]:
    out = {name: _upload(api, f"{name}.glb", rig_glb(rig)) for name, rig in RIGS.items()}
    out["fox"] = _upload(api, "Fox.glb", (data_dir / "Fox.glb").read_bytes())
    out["controlled"] = _upload(api, "controlled.glb", draco_glb(rig_glb(CONTROLLED)))
    return out


def _submit(api, mesh_id: str, **params) -> str:
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh_id, "params": params})
    assert r.status_code == 202, r.text
    return r.json()["id"]


def test_every_gait_makes_a_looping_clip_with_its_travel_speed(api, meshes, services):
    jobs = {(rig, gait): _submit(api, meshes[rig], mode=gait, frames=12) for rig, gait in GAIT_CASES}
    for (rig, gait), job_id in jobs.items():
        job = wait_job(api, job_id)
        assert job["state"] == "succeeded", (rig, gait, job, services.logs())
        clip = api.get(f"/v1/clips/{job['result']['clip_id']}").json()
        assert clip["kind"] == "dynamic-pde" and clip["looping"] is True, clip
        assert clip["info"]["gait"]["name"] == gait and clip["info"]["travel"]["speed"] > 0
        assert clip["info"]["travel"]["direction"] == [0.0, 0.0, 1.0]
        legs = {"biped": 2, "quadruped": 4, "hexapod": 6}[rig]
        assert len(clip["info"]["gait"]["legs"]) == legs
        t0, t1 = (api.get(f"/v1/clips/{clip['id']}/frame", params={"t": t}).content for t in (0.0, 1.0))
        assert t0 == t1  # the loop closes exactly


def test_the_fox_trots_and_keeps_its_look(api, meshes, services):
    job = wait_job(api, _submit(api, meshes["fox"], mode="trot", frames=16, overrides={"step_length": 0.25}))
    assert job["state"] == "succeeded", (job, services.logs())
    cid = job["result"]["clip_id"]
    coef = api.get(f"/v1/clips/{cid}/coefficients", headers={"Accept": "application/json"}).json()
    assert coef["travel"]["speed"] > 0 and [leg["foot"] for leg in coef["gait"]["legs"]] == [
        "b_LeftHand_011", "b_RightHand_08", "b_LeftFoot02_018", "b_RightFoot02_022"]
    glb = api.get(f"/v1/clips/{cid}/animation", params={"fps": 30}).content
    assert_glb_clean(glb, "fox trot animation")
    doc = json.loads(glb[20:20 + struct.unpack_from("<I", glb, 12)[0]])
    assert doc["materials"][0]["name"] == "fox_material" and doc["images"]
    assert doc["animations"][0]["extras"]["loop"] is True


def test_a_draco_rig_with_ik_controls_gallops_without_naming_a_joint(api, meshes, services):
    job = wait_job(api, _submit(api, meshes["controlled"], mode="gallop", frames=12))
    assert job["state"] == "succeeded", (job, services.logs())
    cid = job["result"]["clip_id"]
    coef = api.get(f"/v1/clips/{cid}/coefficients", headers={"Accept": "application/json"}).json()
    feet = [leg["foot"] for leg in coef["gait"]["legs"]]
    assert feet == ["IK-hand.L", "IK-hand.R", "IK-foot.L", "IK-foot.R"]
    assert_glb_clean(api.get(f"/v1/clips/{cid}/animation", params={"fps": 30}).content, "Draco rig gallop")


def test_gait_errors_are_clear(api, meshes, services):
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": meshes["quadruped"],
                                   "params": {"mode": "trot", "frames": 5000}})
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_parameter", r.text
    failing = {_submit(api, meshes["quadruped"], mode="tripod"): "the tripod gait needs six or more legs",
               _submit(api, meshes["hexapod"], mode="trot", legs=["toe"]): "no joint named 'toe'"}
    for job_id, message in failing.items():
        job = wait_job(api, job_id)
        assert job["state"] == "failed" and job["attempt"] == 1, (job, services.logs())
        assert message in job["error"]["message"], job
