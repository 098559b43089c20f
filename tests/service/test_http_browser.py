"""HTTP for browsers, through real servers: CORS (off by default, preflight and refusal), gzip (and zstd
for animation GLBs) with working ETags/304, private immutable caching, /docs and /redoc from local files,
and topology tied to a clip."""

from __future__ import annotations

import gzip
import io
import re

import httpx
import numpy as np
import pytest
import zstandard

from .harness import Services, client, make_key, wait_job

POSTGRES_NIGHTLY = True  # routes over the store: CI runs them on SQLite (conftest)

ORIGIN = "http://localhost:5173"
PRIVATE = "private, max-age=31536000, immutable"


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    """A server with CORS for ORIGIN and a worker, plus a second server on the same data with CORS off."""
    svc = Services(module_backend, tmp_path_factory.mktemp("svc"),
                   env_extra={"PDEANIM_CORS_ORIGINS": f"{ORIGIN}, https://app.example.com/"})
    plain = Services(module_backend, tmp_path_factory.mktemp("plain"))
    try:
        svc.start_server()
        svc.start_worker()
        plain.start_server()
        yield svc, plain
    finally:
        svc.stop()
        plain.stop()


@pytest.fixture(scope="module")
def key(services) -> str:
    return make_key(services[0].backend, "alice")


@pytest.fixture(scope="module")
def api(services, key):
    with client(services[0], key) as c:
        yield c


CYCLIC = {"mode": "eel", "frames": 8, "n_curves": 12, "points": 16, "modes": 3}


@pytest.fixture(scope="module")
def sphere(api, data_dir) -> dict:
    """The fish mesh with two clips of different kinds: a fit of uploaded poses (a travelling sideways wave,
    12 frames) and a cyclic swim."""
    mesh = api.post("/v1/meshes", files={"file": ("fish.obj", (data_dir / "fish_eel.obj").read_bytes(),
                                                  "application/octet-stream")})
    assert mesh.status_code == 201, mesh.text
    mid = mesh.json()["id"]
    verts = np.array([line.split()[1:4] for line in (data_dir / "fish_eel.obj").read_text().splitlines()
                      if line.startswith("v ")], dtype=np.float32)
    axis = int(np.argmax(np.ptp(verts, axis=0)))
    side = (axis + 1) % 3
    u = (verts[:, axis] - verts[:, axis].min()) / np.ptp(verts[:, axis])
    phase = np.linspace(0, 2 * np.pi, 12)[:, None]
    frames = np.repeat(verts[None], 12, axis=0)
    frames[:, :, side] += 0.05 * np.ptp(verts[:, axis]) * u * np.sin(2 * np.pi * u - phase)
    buf = io.BytesIO()
    np.savez(buf, vertices=frames)
    poses = api.post(f"/v1/meshes/{mid}/poses",
                     files={"file": ("p.npz", buf.getvalue(), "application/octet-stream")})
    assert poses.status_code == 201, poses.text
    clips = {}
    for kind, body in (("fit", {"poses_id": poses.json()["id"], "params": {"segments": 2}}),
                       ("cyclic", {"mesh_id": mid, "params": CYCLIC})):
        r = api.post("/v1/jobs", json={"kind": kind, **body})
        assert r.status_code == 202, r.text
        job = wait_job(api, r.json()["id"], timeout=300)
        assert job["state"] == "succeeded", job
        clips[kind] = api.get(f"/v1/clips/{job['result']['clip_id']}").json()
    return {"mesh_id": mid, "poses_id": poses.json()["id"], **clips}


def assert_error(r: httpx.Response, status: int, code: str | None = None) -> dict:
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error"} and set(body["error"]) == {"code", "message"} and body["error"]["message"]
    if code:
        assert body["error"]["code"] == code, body
    return body["error"]


def raw_get(base: str, path: str, headers: dict[str, str]) -> tuple[httpx.Response, bytes]:
    """GET without httpx's transparent decoding: the response and the bytes as they came over the wire."""
    with httpx.Client(base_url=base, timeout=60) as c, c.stream("GET", path, headers=headers) as r:
        return r, b"".join(r.iter_raw())


def test_cors_preflight_and_simple_requests_for_allowed_origins(services, api, sphere):
    svc, _ = services
    path = f"/v1/clips/{sphere['fit']['id']}/coefficients"
    pre = httpx.options(svc.url + path, headers={
        "Origin": ORIGIN, "Access-Control-Request-Method": "GET",
        "Access-Control-Request-Headers": "authorization, if-none-match"})
    assert pre.status_code == 200, pre.text
    assert pre.headers["access-control-allow-origin"] == ORIGIN
    assert "GET" in pre.headers["access-control-allow-methods"]
    assert "authorization" in pre.headers["access-control-allow-headers"].lower()
    assert "access-control-allow-credentials" not in pre.headers  # keys travel in a header, never cookies
    r = api.get(path, headers={"Origin": "https://app.example.com"})  # configured with a trailing slash
    assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "https://app.example.com"
    assert "etag" in r.headers["access-control-expose-headers"].lower()
    assert "Origin" in r.headers["vary"]
    # an error still carries the CORS headers, so the page can read the reason
    err = api.get("/v1/clips/clip_nope", headers={"Origin": ORIGIN})
    assert_error(err, 404, "not_found")
    assert err.headers["access-control-allow-origin"] == ORIGIN


def test_cors_refuses_other_origins_with_the_error_shape(services, api, sphere):
    svc, _ = services
    path = f"/v1/clips/{sphere['fit']['id']}"
    pre = httpx.options(svc.url + path, headers={"Origin": "https://evil.example",
                                                  "Access-Control-Request-Method": "GET"})
    err = assert_error(pre, 400, "cors_refused")
    assert "origin" in err["message"].lower() and "PDEANIM_CORS_ORIGINS" in err["message"]
    r = api.get(path, headers={"Origin": "https://evil.example"})
    assert r.status_code == 200 and "access-control-allow-origin" not in r.headers


def test_cors_is_off_by_default(services, key, sphere):
    _, plain = services
    path = f"/v1/clips/{sphere['fit']['id']}"
    pre = httpx.options(plain.url + path, headers={"Origin": ORIGIN, "Access-Control-Request-Method": "GET"})
    assert_error(pre, 405, "method_not_allowed")
    r = httpx.get(plain.url + path, headers={"Origin": ORIGIN, "Authorization": f"Bearer {key}"})
    assert r.status_code == 200 and not any(h.startswith("access-control-") for h in r.headers)


@pytest.mark.parametrize("route", ["coefficients-json", "animation", "coefficients", "topology"])
def test_gzip_when_accepted_with_weak_etag_and_304(services, key, sphere, route):
    svc, _ = services
    cid = sphere["fit"]["id"]
    path, extra = {"coefficients-json": (f"/v1/clips/{cid}/coefficients", {"Accept": "application/json"}),
                   "animation": (f"/v1/clips/{cid}/animation?fps=10", {}),
                   "coefficients": (f"/v1/clips/{cid}/coefficients", {}),
                   "topology": (f"/v1/clips/{cid}/topology", {})}[route]
    auth = {"Authorization": f"Bearer {key}", **extra}
    plain, plain_body = raw_get(svc.url, path, {**auth, "Accept-Encoding": "identity"})
    assert plain.status_code == 200 and "content-encoding" not in plain.headers
    assert plain.headers["cache-control"] == PRIVATE
    zipped, wire = raw_get(svc.url, path, {**auth, "Accept-Encoding": "gzip, deflate"})
    assert zipped.status_code == 200 and zipped.headers["content-encoding"] == "gzip"
    assert gzip.decompress(wire) == plain_body and len(wire) < len(plain_body)
    if route == "coefficients-json":  # streamed as it is written (memory bounded by a piece): chunked
        assert "content-length" not in zipped.headers and zipped.headers["transfer-encoding"] == "chunked"
    else:
        assert int(zipped.headers["content-length"]) == len(wire)
    assert "accept-encoding" in zipped.headers["vary"].lower()
    assert zipped.headers["cache-control"] == PRIVATE
    strong = plain.headers["etag"]
    assert not strong.startswith("W/") and zipped.headers["etag"] == "W/" + strong
    for tag in (strong, zipped.headers["etag"]):
        for enc in ("gzip", "identity"):
            again, body = raw_get(svc.url, path, {**auth, "Accept-Encoding": enc, "If-None-Match": tag})
            assert again.status_code == 304 and body == b"", (tag, enc)


@pytest.mark.parametrize("accept, coding", [("gzip, deflate, br, zstd", "zstd"), ("zstd;q=0, gzip", "gzip"),
                                             ("gzip;q=0", None), ("*", "zstd"), ("identity", None)])
def test_animation_glb_content_coding_follows_accept_encoding(services, key, sphere, accept, coding):
    """zstd where accepted (a third of gzip's CPU for a smaller body), else gzip, else the GLB as it is."""
    svc, _ = services
    path = f"/v1/clips/{sphere['fit']['id']}/animation?fps=12"
    auth = {"Authorization": f"Bearer {key}"}
    plain, plain_body = raw_get(svc.url, path, {**auth, "Accept-Encoding": "identity"})
    r, wire = raw_get(svc.url, path, {**auth, "Accept-Encoding": accept})
    assert r.status_code == 200 and r.headers.get("content-encoding") == coding, r.headers
    assert int(r.headers["content-length"]) == len(wire)
    assert "accept-encoding" in r.headers["vary"].lower()
    decode = {"zstd": lambda b: zstandard.ZstdDecompressor().decompressobj().decompress(b),
              "gzip": gzip.decompress, None: lambda b: b}[coding]
    assert (decode(wire) == plain_body and wire[:4] != b"glTF") if coding else wire == plain_body
    assert r.headers["etag"] == (f"W/{plain.headers['etag']}" if coding else plain.headers["etag"])
    again, empty = raw_get(svc.url, path,
                           {**auth, "Accept-Encoding": accept, "If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and empty == b""


@pytest.mark.parametrize("route", ["frame", "poses"])
def test_float32_frames_are_sent_as_they_are(services, key, sphere, route):
    """Frame GLBs and poses are raw float32 frames: gzip would save ~16% at ~10x the CPU of the frame."""
    svc, _ = services
    path = {"frame": f"/v1/clips/{sphere['fit']['id']}/frame?t=0.25",
            "poses": f"/v1/poses/{sphere['poses_id']}"}
    auth = {"Authorization": f"Bearer {key}", "Accept-Encoding": "gzip"}
    r, body = raw_get(svc.url, path[route], auth)
    assert r.status_code == 200 and "content-encoding" not in r.headers and len(body) > 1024
    assert int(r.headers["content-length"]) == len(body) and r.headers["cache-control"] == PRIVATE
    assert not r.headers["etag"].startswith("W/")
    again, empty = raw_get(svc.url, path[route], {**auth, "If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and empty == b"" and "content-encoding" not in again.headers


def test_small_and_already_compressed_bodies_are_sent_as_they_are(services, api, sphere):
    svc, _ = services
    health, body = raw_get(svc.url, "/healthz", {"Accept-Encoding": "gzip"})
    assert health.status_code == 200 and "content-encoding" not in health.headers and len(body) < 1024
    png, _ = raw_get(svc.url, "/static/vendor/swagger-ui/favicon-32x32.png", {"Accept-Encoding": "gzip"})
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert "content-encoding" not in png.headers


def test_authenticated_immutable_resources_are_private(api, sphere):
    cid, mid = sphere["fit"]["id"], sphere["mesh_id"]
    for path in (f"/v1/clips/{cid}/coefficients", f"/v1/clips/{cid}/topology", f"/v1/clips/{cid}/frame?t=0.5",
                 f"/v1/clips/{cid}/animation?fps=5", f"/v1/meshes/{mid}/topology?clip_id={cid}",
                 f"/v1/poses/{sphere['poses_id']}"):
        r = api.get(path)
        assert r.status_code == 200 and r.headers["cache-control"] == PRIVATE, (path, r.headers)
    for path in (f"/v1/clips/{cid}", f"/v1/meshes/{mid}", "/healthz", "/viewer", "/docs"):
        assert "public" not in api.get(path).headers.get("cache-control", ""), path


SCRIPT_OR_LINK = re.compile(r"""(?:src|href)\s*=\s*["']([^"']+)["']""")


@pytest.mark.parametrize("page,needle", [("/docs", "swagger-ui-bundle.js"),
                                         ("/redoc", "redoc.standalone.js")])
def test_docs_pages_load_everything_from_the_service(services, page, needle):
    svc, _ = services
    with httpx.Client(base_url=svc.url, timeout=60) as c:
        html = c.get(page)
        assert html.status_code == 200 and html.headers["content-type"].startswith("text/html")
        urls = SCRIPT_OR_LINK.findall(html.text) + re.findall(r"""url:\s*['"]([^'"]+)['"]""", html.text)
        assert any(needle in u for u in urls), urls
        assert "openapi.json" in html.text
        for url in urls:
            assert url.startswith("/"), f"{page} loads {url} from outside the service"
            r = c.get(url)
            assert r.status_code == 200 and len(r.content) > 0, url
        assert "fonts.googleapis" not in html.text and "cdn." not in html.text


def test_topology_belongs_to_a_clip(api, services, sphere):
    fit, cyc, mid = sphere["fit"], sphere["cyclic"], sphere["mesh_id"]
    assert fit["topology_id"] != cyc["topology_id"]  # two kinds on one mesh: the case that used to mix up
    for clip in (fit, cyc):
        topo = api.get(f"/v1/clips/{clip['id']}/topology")
        assert topo.status_code == 200 and topo.content[:8] == b"PDEANIM\0"
        assert topo.headers["etag"].removeprefix("W/") == f'"{clip["topology_id"]}"'  # W/ when gzipped
        old = api.get(f"/v1/meshes/{mid}/topology", params={"clip_id": clip["id"]})
        assert old.status_code == 200 and old.content == topo.content
    err = assert_error(api.get(f"/v1/meshes/{mid}/topology"), 422, "clip_id_required")
    assert "clip_id" in err["message"] and "/v1/clips/" in err["message"]
    other = api.post("/v1/meshes", files={"file": ("t.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                                    b"f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", "text/plain")})
    assert other.status_code == 201, other.text
    assert_error(api.get(f"/v1/meshes/{other.json()['id']}/topology", params={"clip_id": fit["id"]}), 404)
    with client(services[0], make_key(services[0].backend, "mallory")) as mallory:
        assert_error(mallory.get(f"/v1/clips/{fit['id']}/topology"), 404, "not_found")
    assert_error(client(services[0], None).get(f"/v1/clips/{fit['id']}/topology"), 401, "unauthorized")


def test_mesh_file_is_served_as_uploaded_with_its_media_type(api, services, sphere, data_dir):
    mid = sphere["mesh_id"]
    r = api.get(f"/v1/meshes/{mid}/file")
    assert r.status_code == 200, r.text
    assert r.content == (data_dir / "fish_eel.obj").read_bytes()
    assert r.headers["content-type"].split(";")[0] == "model/obj"
    assert r.headers["cache-control"] == PRIVATE
    assert f'filename="{mid}.obj"' in r.headers["content-disposition"]
    again = api.get(f"/v1/meshes/{mid}/file", headers={"If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and again.content == b""
    assert_error(api.get("/v1/meshes/mesh_00000000000000000000000000000000/file"), 404, "not_found")
    with client(services[0], make_key(services[0].backend, "mallory")) as mallory:
        assert_error(mallory.get(f"/v1/meshes/{mid}/file"), 404, "not_found")
    assert_error(client(services[0], None).get(f"/v1/meshes/{mid}/file"), 401, "unauthorized")


@pytest.mark.parametrize("accept", ["gzip, deflate, br, zstd", "identity"])
def test_animation_head_gives_the_size_get_sends(services, key, sphere, accept):
    """HEAD of the animation: the headers GET sends (its Content-Length in the same coding), no body; the
    viewer shows the size without downloading the GLB."""
    svc, _ = services
    path = f"/v1/clips/{sphere['fit']['id']}/animation?fps=12"
    headers = {"Authorization": f"Bearer {key}", "Accept-Encoding": accept}
    got, wire = raw_get(svc.url, path, headers)
    with httpx.Client(base_url=svc.url, timeout=60) as c:
        head = c.head(path, headers=headers)
        missing = c.head(path.replace(sphere["fit"]["id"], "clip_none"), headers=headers)
    assert head.status_code == 200 and head.content == b""
    assert int(head.headers["content-length"]) == len(wire) == int(got.headers["content-length"])
    assert head.headers.get("content-encoding") == got.headers.get("content-encoding")
    assert missing.status_code == 404
