"""The streamable layout over HTTP (docs/http.md): ``GET .../coefficients?layout=stream`` with byte ranges
(Range, 206, 416, If-Range), one ETag for the part and one per window, conditional requests, per-window bodies
that decode with the part's head alone, and the plain layout unchanged for current clients."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pdeanim import container
from pdeanim.clip import ClipParts, load_clip, read_clip_file
from pdeanim.model.clipformat import decode_topology
from pdeanim.model.streamlayout import StreamClip, read_index
from pdeanim_service.store.context import Store

from .conftest import running_services

pytestmark = pytest.mark.slow  # a real server and worker start for this module (as in test_bone_clips.py)
FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"
OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
WINDOW_SECONDS = "0.1"  # the fixtures last half a second: several windows each


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    env = {"PDEANIM_STREAM_WINDOW_SECONDS": WINDOW_SECONDS}
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"), env)


@pytest.fixture(scope="module")
def store(services):
    st = Store.open(services.backend.settings())
    yield st
    st.close()


def _stored_clip(api, store: Store, clip_id: str, parts: ClipParts, kind: str = "dynamic-pde") -> None:
    """A clip row for ``parts`` on a mesh of the calling tenant (as a fit job would leave it)."""
    from pdeanim_service.store.models import ClipRecord, Mesh

    r = api.post("/v1/meshes", files={"file": ("m.obj", OBJ, "application/octet-stream")})
    assert r.status_code in (200, 201), r.text
    with store.sessions() as s:
        tenant = s.get(Mesh, r.json()["id"]).tenant_id
        s.add(ClipRecord(id=clip_id, tenant_id=tenant, mesh_id=r.json()["id"], kind=kind,
                         topology_key=store.blobs.put(parts.topology),
                         coefficients_key=store.blobs.put(parts.coefficients),
                         topology_id=parts.topology_id, report={}))
        s.commit()


@pytest.fixture(scope="module")
def spline_clip(api, store):
    parts = read_clip_file(FIXTURES / "bones-synthetic-k4-residual.clip")  # bones, spline items, 3 windows+
    _stored_clip(api, store, "clip_stream_1", parts)
    return "clip_stream_1", parts


def test_the_stream_layout_plays_the_clip(api, spline_clip):
    clip_id, parts = spline_clip
    r = api.get(f"/v1/clips/{clip_id}/coefficients", params={"layout": "stream"})
    assert r.status_code == 200, r.text
    assert r.headers["accept-ranges"] == "bytes" and "content-encoding" not in r.headers
    header, _, windows = read_index(r.content)
    assert header["required"] == ["bones", "stream"] and header["format_version"] == "1.2"
    assert int(r.headers["x-pdeanim-windows"]) == len(windows) >= 3
    stream, source = load_clip(parts.topology, r.content), load_clip(parts.topology, parts.coefficients)
    t = np.linspace(0.0, 1.0, 41)
    np.testing.assert_allclose(stream.evaluate(t), source.evaluate(t), rtol=0, atol=1e-6)
    plain = api.get(f"/v1/clips/{clip_id}/coefficients")  # current clients: the stored bytes, as before
    assert plain.status_code == 200 and plain.content == parts.coefficients
    assert plain.headers["etag"].strip('W/"') != r.headers["etag"].strip('"')
    js = api.get(f"/v1/clips/{clip_id}/coefficients", params={"layout": "stream"},
                 headers={"Accept": "application/json"})
    assert js.status_code == 200 and js.json()["stream"]["n_windows"] == len(windows)


def test_byte_ranges(api, spline_clip):
    clip_id, _ = spline_clip
    path = f"/v1/clips/{clip_id}/coefficients"
    whole = api.get(path, params={"layout": "stream"})
    body, etag, n = whole.content, whole.headers["etag"], len(whole.content)
    _, _, windows = read_index(body)
    w0 = windows[0]
    r = api.get(path, params={"layout": "stream"}, headers={"Range": f"bytes=0-{w0.end - 1}"})
    assert r.status_code == 206 and r.content == body[:w0.end]
    assert r.headers["content-range"] == f"bytes 0-{w0.end - 1}/{n}" and r.headers["etag"] == etag
    for spec, lo, hi in ((f"bytes={w0.start}-", w0.start, n - 1), ("bytes=-100", n - 100, n - 1),
                         (f"bytes=5-{n + 50}", 5, n - 1)):
        r = api.get(path, params={"layout": "stream"}, headers={"Range": spec})
        assert r.status_code == 206 and r.content == body[lo:hi + 1], spec
        assert r.headers["content-range"] == f"bytes {lo}-{hi}/{n}"
    for spec in (f"bytes={n}-", f"bytes={n + 10}-{n + 20}", "bytes=-0"):
        r = api.get(path, params={"layout": "stream"}, headers={"Range": spec})
        assert r.status_code == 416, spec
        assert r.headers["content-range"] == f"bytes */{n}"
        assert r.json()["error"]["code"] == "range_not_satisfiable"
    for spec in ("bytes=0-1,4-5", "items=0-4", "bytes=9-3", "bytes=x-"):  # ignored: the whole body
        r = api.get(path, params={"layout": "stream"}, headers={"Range": spec})
        assert r.status_code == 200 and r.content == body, spec
    r = api.get(path, params={"layout": "stream"}, headers={"Range": "bytes=0-9", "If-Range": etag})
    assert r.status_code == 206 and r.content == body[:10]
    r = api.get(path, params={"layout": "stream"}, headers={"Range": "bytes=0-9", "If-Range": '"other"'})
    assert r.status_code == 200 and r.content == body
    assert api.get(path, params={"layout": "stream"}, headers={"If-None-Match": etag}).status_code == 304


def test_windows_with_their_own_etags(api, spline_clip):
    clip_id, parts = spline_clip
    body = api.get(f"/v1/clips/{clip_id}/coefficients", params={"layout": "stream"}).content
    _, _, windows = read_index(body)
    topo = decode_topology(*container.unpack(parts.topology))
    whole = StreamClip(topo, body)
    head = StreamClip.from_prefix(topo, body[:windows[0].start]).head  # header, index and head: no window
    tags = set()
    for w in windows:
        r = api.get(f"/v1/clips/{clip_id}/coefficients/windows/{w.index}")
        assert r.status_code == 200, r.text
        assert r.headers["accept-ranges"] == "bytes" and r.headers["etag"] not in tags
        tags.add(r.headers["etag"])
        if w.index == 0:
            assert r.content == body[w.start:w.end]
        t = np.linspace(w.t0, w.t1, 5)[:-1]  # decoded from the head and this body alone (a seek)
        np.testing.assert_array_equal(head.window(w.index, r.content).evaluate(t), whole.evaluate(t))
        again = api.get(f"/v1/clips/{clip_id}/coefficients/windows/{w.index}",
                        headers={"If-None-Match": r.headers["etag"]})
        assert again.status_code == 304 and again.headers["etag"] == r.headers["etag"]
        part = api.get(f"/v1/clips/{clip_id}/coefficients/windows/{w.index}", headers={"Range": "bytes=0-15"})
        assert part.status_code == 206 and part.content == r.content[:16]
    r = api.get(f"/v1/clips/{clip_id}/coefficients/windows/{len(windows)}")
    assert r.status_code == 404 and r.json()["error"]["code"] == "window_not_found"


def test_a_cyclic_clip_has_no_stream_layout_and_other_tenants_see_nothing(api, other, store, spline_clip):
    parts = read_clip_file(FIXTURES / "cyclic-eel-standing-rotate.clip")
    _stored_clip(api, store, "clip_stream_cyclic", parts, kind="cyclic-spine")
    r = api.get("/v1/clips/clip_stream_cyclic/coefficients", params={"layout": "stream"})
    assert r.status_code == 422 and r.json()["error"]["code"] == "not_streamable"
    assert api.get("/v1/clips/clip_stream_cyclic/coefficients", params={"layout": "other"}).status_code == 422
    clip_id, _ = spline_clip
    assert other.get(f"/v1/clips/{clip_id}/coefficients", params={"layout": "stream"}).status_code == 404
    assert other.get(f"/v1/clips/{clip_id}/coefficients/windows/0").status_code == 404
