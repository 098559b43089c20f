"""Fair, bounded uploads: slots per tenant plus a cap in all (429 with Retry-After past them), and a minimum
body rate (408), so a tenant that sends its bodies a byte at a time (slowloris) holds only its own slots,
for a bounded time, and another tenant's upload is not delayed by more than 2 s (the goal of issue 34)."""

from __future__ import annotations

import select
import socket
import time

import httpx
import pytest

from pdeanim_service.api.errors import ApiError
from pdeanim_service.api.uploadslots import BodyPace, UploadSlots

from .harness import Services, client, make_key

POSTGRES_NIGHTLY = True  # upload scheduling, the same on both backends: CI runs it on SQLite (conftest)

TET_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
BOUNDARY = "slowloris-boundary"
DELAY_BOUND = 2.0  # seconds another tenant's upload may be delayed by the slow one (issue 34's goal)
GRACE = 8.0  # PDEANIM_UPLOAD_BODY_GRACE_SECONDS of the server below


def test_slots_per_tenant_and_in_all_refuse_with_429_and_retry_after():
    slots = UploadSlots(total=3, per_tenant=2)
    with slots.hold("a"), slots.hold("a"):
        with pytest.raises(ApiError) as info, slots.hold("a"):
            pass
        assert info.value.status_code == 429 and info.value.headers["Retry-After"] == "2"
        assert "PDEANIM_MAX_TENANT_UPLOADS" in info.value.detail
        with slots.hold("b"):  # another tenant still gets the last slot
            with pytest.raises(ApiError) as info, slots.hold("c"):
                pass
            assert info.value.status_code == 429 and "PDEANIM_MAX_CONCURRENT_UPLOADS" in info.value.detail
    assert slots.active == 0 and slots.by_tenant == {}


def test_body_pace_allows_the_grace_then_the_minimum_rate():
    pace, now = BodyPace(min_rate=1000.0, grace=5.0), time.monotonic()
    assert 4.5 < pace.seconds_left(now, 0) <= 5.0
    assert 6.5 < pace.seconds_left(now, 2000) <= 7.0  # 2000 bytes bought 2 s more
    assert pace.seconds_left(now - 10.0, 1000) < 0  # 1000 bytes in 10 s: behind
    assert BodyPace(0.0, 5.0).seconds_left(now, 0) is None  # no minimum
    assert pace.too_slow(now, 10).status_code == 408


def _slow_upload(port: int, key: str) -> socket.socket:
    """Start an upload that sends its headers and the file part's head, then nothing more."""
    head = (f"--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"slow.obj\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n").encode()
    length = len(head) + 100_000
    sock = socket.create_connection(("127.0.0.1", port), timeout=60)
    sock.sendall(f"POST /v1/meshes HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {key}\r\n"
                 f"Content-Type: multipart/form-data; boundary={BOUNDARY}\r\nContent-Length: {length}\r\n\r\n"
                 .encode() + head)
    return sock


def _answer(sock: socket.socket, timeout: float = 60.0) -> tuple[int, bytes]:
    """The status and raw bytes of the answer on ``sock`` (waits for it)."""
    sock.settimeout(timeout)
    data = b""
    while b"\r\n\r\n" not in data or b"}" not in data:
        chunk = sock.recv(65536)
        if not chunk:
            break
        data += chunk
    return int(data.split(b" ", 2)[1]), data


def _answered(sock: socket.socket) -> bool:
    return bool(select.select([sock], [], [], 0)[0])


def _timed_upload(api: httpx.Client) -> float:
    started = time.monotonic()
    r = api.post("/v1/meshes", files={"file": ("tet.obj", TET_OBJ)})
    assert r.status_code == 201, r.text
    return time.monotonic() - started


def test_a_slowloris_tenant_does_not_delay_another_tenants_upload(backend, tmp_path):
    svc = Services(backend, tmp_path / "logs", env_extra={
        "PDEANIM_WARM_START": "false", "PDEANIM_MAX_TENANT_UPLOADS": "2",
        "PDEANIM_MAX_CONCURRENT_UPLOADS": "4",
        "PDEANIM_UPLOAD_BODY_GRACE_SECONDS": str(GRACE), "PDEANIM_UPLOAD_MIN_BYTES_PER_SECOND": "1000"})
    svc.start_server("--workers", "1")
    slow_key, fast_key = make_key(backend, "slowloris"), make_key(backend, "victim")
    sockets: list[socket.socket] = []
    try:
        with client(svc, fast_key) as api:
            baseline = min(_timed_upload(api) for _ in range(3))  # the first also starts the validators
            started = time.monotonic()
            sockets = [_slow_upload(svc.port, slow_key) for _ in range(6)]
            refused = []
            while len(refused) < 4 and time.monotonic() - started < GRACE:
                refused += [s for s in select.select(sockets, [], [], 0.1)[0] if s not in refused]
            for extra in refused:  # the tenant's two slots are taken: its other uploads are refused
                status, raw = _answer(extra)
                assert status == 429 and b"retry-after: 2" in raw.lower(), raw
                assert b"PDEANIM_MAX_TENANT_UPLOADS" in raw
            held = [s for s in sockets if s not in refused]
            assert len(held) == 2, len(held)
            delayed = _timed_upload(api)
            assert not any(_answered(s) for s in held) and time.monotonic() - started < GRACE, \
                "the slow uploads were no longer holding their slots: the check proves nothing"
            assert delayed <= baseline + DELAY_BOUND, (delayed, baseline)
        for sock in held:  # then the slow bodies time out, with 408 naming the settings
            status, raw = _answer(sock)
            assert status == 408 and b"PDEANIM_UPLOAD_MIN_BYTES_PER_SECOND" in raw, raw
            assert time.monotonic() - started < GRACE + 30
        with client(svc, slow_key) as slow_api:  # their slots are free again
            assert _timed_upload(slow_api) > 0
    finally:
        for sock in sockets:
            sock.close()
        svc.stop()
    print(f"upload alone {baseline:.2f} s, beside a slowloris tenant {delayed:.2f} s")
