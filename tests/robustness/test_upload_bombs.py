"""Issue 26 (uploads that cannot take the API down), through a real API process: each file of the audit's
corpus (generated here) is refused with a 4xx that gives the figures, quickly, and the API process's peak
memory (VmHWM from /proc) grows by less than 50 MB, whatever the file declares; legal uploads that inflate
to hundreds of MB are validated in a child process, not in the API; a body 20x the copy buffer streams to
the blob store; uploads past the concurrency limit get 429 with Retry-After."""

from __future__ import annotations

import io
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
import trimesh

from ..service.conftest import Backend
from ..service.harness import Services, client, make_key
from . import bombs

MB = 1024 * 1024
GROWTH = 50 * MB  # what the issue allows the API process to grow by for any file
FAST = 30.0  # wall seconds of a refusal from declared sizes through HTTP on this shared 2-core machine (at a
# load of 17 the 200k-primitive flood took 10 s here for 0.55 s of CPU, mostly parsing its 8 MB of JSON;
# the old code took 12.4 s unloaded); the CPU-time bound of 1 s is tested in test_decode_limits.py
UPLOAD_MEMORY = 512 * MB  # the validator child's budget in these tests


def vm_kib(pid: int, field: str) -> int:
    """A VmRSS/VmHWM figure of a process from /proc, in bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no {field} for process {pid}")


def reset_peak(pid: int) -> int:
    """Reset the process's VmHWM to its VmRSS (``clear_refs`` 5, Linux 4.0+), so a peak reached by an
    earlier test does not hide this one's; returns the VmRSS to measure growth from."""
    try:
        Path(f"/proc/{pid}/clear_refs").write_text("5")
        return vm_kib(pid, "VmRSS")
    except OSError:  # not allowed here: measure from the peak so far
        return vm_kib(pid, "VmHWM")


@pytest.fixture(scope="module")
def api(tmp_path_factory) -> Iterator[tuple[Services, httpx.Client]]:
    """One API process (a single HTTP process, so its pid is the one serving) for the module."""
    tmp = tmp_path_factory.mktemp("bombs")
    svc = Services(Backend("sqlite", {"PDEANIM_DATA_DIR": str(tmp / "data"),
                                      "PDEANIM_UPLOAD_MEMORY_BYTES": str(UPLOAD_MEMORY),
                                      "PDEANIM_MAX_CONCURRENT_UPLOADS": "1"}), tmp)
    svc.start_server("--workers", "1")
    with client(svc, make_key(svc.backend, "bombs")) as http:
        warm = http.post("/v1/meshes", files={"file": ("warm.glb", bombs.pack_glb(*bombs._tetra_doc()))})
        assert warm.status_code == 201, warm.text  # imports of the first upload are not counted below
        yield svc, http
    svc.stop()


def refused(api, name: str, data: bytes, path: str = "/v1/meshes") -> tuple[httpx.Response, float]:
    """POST ``data`` as file ``name``; the answer and its seconds, after checking the API's peak memory."""
    svc, http = api
    before = reset_peak(svc.server.pid)
    started = time.monotonic()
    r = http.post(path, files={"file": (name, data)})
    elapsed = time.monotonic() - started
    growth = vm_kib(svc.server.pid, "VmHWM") - before
    assert growth < GROWTH, f"{name}: the API process grew by {growth / MB:.0f} MB"
    assert 400 <= r.status_code < 500 and r.json()["error"]["message"], r.text
    return r, elapsed


@pytest.mark.parametrize("views", [1, 3])
def test_meshopt_bomb_is_refused_before_decoding(api, views: int) -> None:
    """Views that decode to 1 GiB (512 MiB x 3 sharing one stream) for a 4-vertex mesh."""
    size = (1 << 30) if views == 1 else (1 << 29)
    r, elapsed = refused(api, "bomb.glb", bombs.meshopt_bomb(size, views))
    message = r.json()["error"]["message"]
    assert r.status_code == 422 and f"declares {size} decoded bytes" in message and "read 60" in message
    assert elapsed < FAST, elapsed


def test_deep_json_is_a_4xx_naming_the_limit(api) -> None:
    r, elapsed = refused(api, "deep.glb", bombs.deep_json(100_000))
    assert r.status_code == 413 and "PDEANIM_MAX_GLTF_JSON_DEPTH" in r.json()["error"]["message"], r.text
    assert "100001" in r.json()["error"]["message"] and elapsed < FAST


@pytest.mark.parametrize(("kind", "setting"), [("nodes", "PDEANIM_MAX_GLTF_NODES"),
                                               ("primitives", "PDEANIM_MAX_GLTF_PRIMITIVES")])
def test_floods_are_refused_from_declared_counts(api, kind: str, setting: str) -> None:
    """200k nodes or primitives: refused from the JSON's counts, not after walking the scene (was 32.7 s
    and 12.4 s)."""
    data = bombs.node_flood(200_000) if kind == "nodes" else bombs.primitive_flood(200_000)
    r, elapsed = refused(api, f"{kind}.glb", data)
    assert r.status_code == 413 and setting in r.json()["error"]["message"] and "200000" in r.text, r.text
    assert elapsed < FAST, elapsed


def test_vertices_are_refused_from_declared_counts(api) -> None:
    """Under the primitive limit (19k primitives of 32 vertices), the vertex count the scene declares is
    checked before any primitive is decoded."""
    r, elapsed = refused(api, "many.glb", bombs.primitive_flood(19_000, vertices=32))
    assert r.status_code == 413 and "vertex count the glTF scene declares is 608000" in r.text, r.text
    assert elapsed < FAST


@pytest.mark.parametrize("where", ["accessor", "meshopt"])
def test_counts_past_2_31_are_refused(api, where: str) -> None:
    if where == "accessor":
        data = bombs.accessor_count_bomb(2**31 + 5)
    else:
        data = bombs.meshopt_count_bomb(2**31 + 1)
    r, elapsed = refused(api, "count.glb", data)
    assert r.status_code == 422 and ("2147483653" in r.text or "2147483649" in r.text), r.text
    assert elapsed < FAST


@pytest.fixture(scope="module")
def sphere(api) -> dict:
    """A 40,962-vertex mesh for the poses uploads."""
    ball = trimesh.creation.icosphere(6)
    ply = ball.export(file_type="ply")
    r = api[1].post("/v1/meshes", files={"file": ("ball.ply", ply)})
    assert r.status_code == 201, r.text
    return r.json()


def test_npz_bomb_over_the_memory_budget_is_a_413(api, sphere) -> None:
    """A ~2 MB .npz inflating to 541 MB (legal under the 1 GiB pose limit) needs more than the validator's
    512 MiB: 413 naming the budget, and the API process does not grow."""
    data = bombs.npz_zeros(1100, sphere["vertices"])
    r, elapsed = refused(api, "bomb.npz", data, f"/v1/meshes/{sphere['id']}/poses")
    assert len(data) < 4 * MB and r.status_code == 413, r.text
    assert "PDEANIM_UPLOAD_MEMORY_BYTES" in r.json()["error"]["message"] and elapsed < FAST


def test_legal_npz_bomb_is_validated_outside_the_api(api, sphere) -> None:
    """A ~0.3 MB .npz inflating to 246 MB is accepted, and the API's peak memory stays within 50 MB."""
    svc, http = api
    data = bombs.npz_zeros(500, sphere["vertices"])
    before = reset_peak(svc.server.pid)
    r = http.post(f"/v1/meshes/{sphere['id']}/poses", files={"file": ("legal.npz", data)})
    assert r.status_code == 201 and r.json()["frames"] == 500, r.text
    assert vm_kib(svc.server.pid, "VmHWM") - before < GROWTH


def test_large_upload_streams_with_bounded_memory(api, sphere) -> None:
    """A 40 MiB upload (40x the 1 MiB copy buffer of the blob store) grows the API process by less than
    20 MB: the body goes to disk as it arrives, the validator child reads it there, the blob store copies
    the canonical file in 1 MiB chunks."""
    svc, http = api
    frames = 40 * MB // (sphere["vertices"] * 12) + 1
    rng = np.random.default_rng(0)
    buf = io.BytesIO()
    np.savez(buf, vertices=rng.standard_normal((frames, sphere["vertices"], 3)).astype(np.float32))
    data = buf.getvalue()
    assert len(data) > 40 * MB
    before = reset_peak(svc.server.pid)
    r = http.post(f"/v1/meshes/{sphere['id']}/poses", files={"file": ("big.npz", data)})
    assert r.status_code == 201 and r.json()["frames"] == frames, r.text
    growth = vm_kib(svc.server.pid, "VmHWM") - before
    assert growth < 20 * MB, f"the API grew by {growth / MB:.1f} MB for a {len(data) / MB:.0f} MB upload"


def test_uploads_past_the_limit_get_429_with_retry_after(api) -> None:
    """With PDEANIM_MAX_CONCURRENT_UPLOADS=1, a second upload while one is still being received is refused
    at once with Retry-After; the first then completes."""
    svc, http = api
    release, sending = threading.Event(), threading.Event()
    boundary = "bombs-boundary"
    data = bombs.pack_glb(*bombs._tetra_doc())
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"slow.glb\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n").encode()

    def body() -> Iterator[bytes]:
        yield head + data[:100]
        sending.set()
        release.wait(60)
        yield data[100:] + f"\r\n--{boundary}--\r\n".encode()

    answer: list[httpx.Response] = []
    headers = {**http.headers, "Content-Type": f"multipart/form-data; boundary={boundary}"}
    slow = threading.Thread(target=lambda: answer.append(
        httpx.post(svc.url + "/v1/meshes", content=body(), headers=headers, timeout=60)))
    slow.start()
    scratch = Path(svc.backend.env["PDEANIM_DATA_DIR"]) / "tmp"
    try:
        assert sending.wait(30)
        deadline = time.monotonic() + 60
        while not list(scratch.glob("upload-*")):  # the slow upload holds its slot and is being written
            assert time.monotonic() < deadline, "the slow upload never reached the server's scratch file"
            time.sleep(0.05)
        r = http.post("/v1/meshes", files={"file": ("other.glb", data)})
        assert r.status_code == 429 and r.headers.get("Retry-After") == "2", r.text  # noqa: PLR2004
        assert "PDEANIM_MAX_CONCURRENT_UPLOADS" in r.json()["error"]["message"]
    finally:
        release.set()
        slow.join(60)
    assert answer and answer[0].status_code == 201, answer
