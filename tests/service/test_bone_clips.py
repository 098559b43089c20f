"""Clips with a bone layer (format 1.1) through the HTTP API: a stored clip's frames are the library's
positions, its animation GLB is a skinned one, and a clip that requires a feature the server lacks is
refused with 422 naming it (never a 500)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pdeanim.clip import ClipParts, load_clip, read_clip_file
from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim_service.store.context import Store
from tests.conformance.bonecases import UNKNOWN_FEATURE, unknown_feature_case

from .conftest import running_services

pytestmark = pytest.mark.slow  # a real server and worker start for this module (as in test_exports.py)
FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"
OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"))


@pytest.fixture(scope="module")
def store(services):
    st = Store.open(services.backend.settings())
    yield st
    st.close()


def _stored_clip(api, store: Store, clip_id: str, parts: ClipParts) -> None:
    """A clip row for ``parts`` on a mesh of the calling tenant (as a fit job would leave it)."""
    from pdeanim_service.store.models import ClipRecord, Mesh

    r = api.post("/v1/meshes", files={"file": ("m.obj", OBJ, "application/octet-stream")})
    assert r.status_code in (200, 201), r.text
    mesh_id = r.json()["id"]
    with store.sessions() as s:
        tenant = s.get(Mesh, mesh_id).tenant_id
        s.add(ClipRecord(id=clip_id, tenant_id=tenant, mesh_id=mesh_id, kind="dynamic-pde",
                         topology_key=store.blobs.put(parts.topology),
                         coefficients_key=store.blobs.put(parts.coefficients),
                         topology_id=parts.topology_id, report={}))
        s.commit()


def _positions(glb: bytes) -> np.ndarray:
    """(V, 3) float32 POSITION of the first primitive of a plain float32 GLB."""
    doc, binary = unpack_glb(glb)
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(binary, np.float32, acc["count"] * 3, start).reshape(-1, 3)


def test_frames_and_animation_of_a_clip_with_bones(api, store):
    parts = read_clip_file(FIXTURES / "bones-fit-k4-residual.clip")
    _stored_clip(api, store, "clip_bones_1", parts)
    clip = load_clip(parts.topology, parts.coefficients)
    info = api.get("/v1/clips/clip_bones_1")
    assert info.status_code == 200, info.text
    assert info.json()["info"]["bones"]["n_bones"] == 5
    for t in (0.0, 0.3, 1.0):
        r = api.get("/v1/clips/clip_bones_1/frame", params={"t": t})
        assert r.status_code == 200, r.text
        np.testing.assert_array_equal(_positions(r.content), clip.evaluate(t))
    r = api.get("/v1/clips/clip_bones_1/animation", params={"fps": 12})
    assert r.status_code == 200, r.text
    doc, _ = unpack_glb(r.content)
    assert len(doc["skins"][0]["joints"]) == 5  # the OBJ does not match the clip: plain, so skinned
    assert_clean(validate_many([r.content])[0], "HTTP animation of a clip with bones")


def test_a_clip_requiring_an_unknown_feature_is_refused_with_422(api, store):
    _stored_clip(api, store, "clip_future_1", unknown_feature_case())
    r = api.get("/v1/clips/clip_future_1/frame", params={"t": 0.5})
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_clip" and UNKNOWN_FEATURE in r.json()["error"]["message"]
