"""Progressive playback from the service in headless Chromium: a long clip, asked for in the streamable layout
(GET /v1/clips/{id}/coefficients?layout=stream), shows its first frame before the last byte of its
coefficients has arrived, as the network events say (CDP dataReceived / loadingFinished over a throttled
network), then plays on into later windows with at most ``maxWindows`` of them decoded."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pdeanim.clip import ClipParts
from tests.service.harness import Services, client, make_key

from .test_viewer import HERE, browser_env, browser_ready  # noqa: F401 - the module's shared browser fixtures

OBJ_SUBDIVISIONS = 3  # a 642-vertex icosphere
SEGMENTS = 600  # 20 s of frames at 30 per second: 10 windows of 2 s
DOWNLOAD_SECONDS = 6.0  # the throttled network takes this long for the whole coefficients part
MAX_WINDOWS = 3


@pytest.fixture(scope="module")
def services(browser_ready, tmp_path_factory):  # noqa: F811 - the browser fixture of test_viewer
    from tests.service.conftest import open_backend

    with open_backend("sqlite", tmp_path_factory.mktemp("data"), None) as backend:
        svc = Services(backend, tmp_path_factory.mktemp("svc"))
        try:
            svc.start_server()
            yield svc
        finally:
            svc.stop()


def long_clip() -> ClipParts:
    """A 600-segment clip of a 642-vertex sphere: the topology and time constants of a short fit, its knots
    a travelling wave (and some noise) over 601 frames (made, not fitted: the test is about bytes and
    windows)."""
    import trimesh

    from pdeanim import container
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.model.clipformat import CoefficientData, decode_coefficients, encode_coefficients
    from pdeanim.poses import make_poses

    mesh = trimesh.creation.icosphere(subdivisions=OBJ_SUBDIVISIONS)
    rest = np.asarray(mesh.vertices)
    frames = [rest * (1 + 0.1 * np.sin(2 * np.pi * f / 8 + rest[:, :1])) for f in range(9)]
    short = fit_poses(make_poses(np.stack(frames), np.asarray(mesh.faces), np.arange(9) / 30.0),
                      FitOptions(segments=2, time_model="pde"))
    header, arrays = container.unpack(short.coefficients)
    C = int(header["n_curves"])
    src = decode_coefficients(header, arrays, C)
    S = SEGMENTS
    s = np.arange(S + 1)[:, None, None, None]
    phase = np.arange(C)[None, :, None, None] * 0.37 + np.arange(3)[None, None, :, None]
    scale = np.abs(src.knots[:1]).max()
    noise = np.random.default_rng(5).normal(0.0, 0.002 * scale, (S + 1, *src.knots.shape[1:]))
    knots = src.knots[:1] + 0.05 * scale * np.sin(0.08 * s + phase) + noise  # noise: bytes like a real fit's
    family = np.repeat(src.family[:1], S, axis=0)
    m = np.repeat(np.asarray(src.m)[:1], S, axis=0)
    data = CoefficientData(np.linspace(0.0, 1.0, S + 1), np.arange(S + 1) / 30.0, family, m, src.D, knots,
                           src.motion, False, {"errors": {}}, {}, src.time_model)
    return ClipParts(short.topology, encode_coefficients(short.topology, data))


def stored_clip(services: Services, key: str, clip_id: str, parts: ClipParts) -> None:
    """A clip row for ``parts`` on a mesh of the key's tenant (as a fit job would leave it)."""
    from pdeanim_service.store.context import Store
    from pdeanim_service.store.models import ClipRecord, Mesh

    api = client(services, key)
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    r = api.post("/v1/meshes", files={"file": ("m.obj", obj, "application/octet-stream")})
    assert r.status_code in (200, 201), r.text
    store = Store.open(services.backend.settings())
    try:
        with store.sessions() as s:
            tenant = s.get(Mesh, r.json()["id"]).tenant_id
            s.add(ClipRecord(id=clip_id, tenant_id=tenant, mesh_id=r.json()["id"], kind="dynamic-pde",
                             topology_key=store.blobs.put(parts.topology),
                             coefficients_key=store.blobs.put(parts.coefficients),
                             topology_id=parts.topology_id, report={}))
            s.commit()
    finally:
        store.close()


def test_a_long_clip_plays_from_the_service_before_its_last_byte_arrives(services, browser_env,  # noqa: F811
                                                                        tmp_path):
    key = make_key(services.backend, "stream")
    stored_clip(services, key, "clip_long_stream", long_clip())
    api = client(services, key)
    part = api.get("/v1/clips/clip_long_stream/coefficients", params={"layout": "stream"})
    assert part.status_code == 200, part.text
    total = len(part.content)
    job = {"origin": services.url, "clip": "clip_long_stream", "key": key, "play": 0.26,
           "maxWindows": MAX_WINDOWS, "throughput": max(20_000, int(total / DOWNLOAD_SECONDS)),
           "out": str(tmp_path / "result.json")}
    proc = subprocess.run(["node", str(HERE / "stream_check.mjs"), json.dumps(job)], cwd=HERE,
                          env=browser_env, capture_output=True, text=True, timeout=300)
    result = json.loads(Path(job["out"]).read_text()) if Path(job["out"]).exists() else {}
    assert proc.returncode == 0 and "error" not in result, (proc.stdout, proc.stderr, result, services.logs())
    page = result["page"]
    assert page["streaming"] and page["gpu"] and page["finite"], page
    assert page["nWindows"] >= 8, page

    # the coefficients request of the first load, and the network's clock at the page's first frame
    first_id, first = next((rid, r) for rid, r in result["requests"].items()
                           if "/coefficients?layout=stream" in r["url"] and r["range"] is None)
    offset = first["wallTime"] - first["timestamp"]  # wall clock - the network events' monotonic clock
    at_first_frame = page["firstFrame"] / 1000 - offset
    got = [e for e in result["events"] if e["id"] == first_id]
    received = sum(e["bytes"] for e in got if e["type"] == "data" and e["timestamp"] <= at_first_frame)
    finished = [e["timestamp"] for e in got if e["type"] == "finished"]
    # the first frame was drawn with a small part of the coefficients in: the rest had not arrived
    assert 0 < received < total / 3, (received, total, page)
    assert not finished or finished[0] > at_first_frame, (finished, at_first_frame)
    # and playback went on into later windows as they arrived, never holding more than MAX_WINDOWS
    later = sum(e["bytes"] for e in got if e["type"] == "data" and e["timestamp"] > at_first_frame)
    assert later > 0, "no bytes arrived after the first frame"
    assert len(page["windowsShown"]) >= 3 and page["windowsShown"] == sorted(page["windowsShown"]), page
    assert page["mostDecoded"] <= MAX_WINDOWS, page
