"""The frame hot path through real HTTP (two API processes, as ``pdeanim serve`` starts by default on two
CPUs): cached frames are byte-identical to freshly computed ones, a revoked key stops working within the key
cache's TTL, and job processes run at a lower CPU priority."""

from __future__ import annotations

import os
import time
from pathlib import Path

import httpx
import pytest
from sqlalchemy import update

from pdeanim_service.api.cache import BodyCache
from pdeanim_worker.child import lower_priority
from tests.ci import missing

from .conftest import running_services
from .harness import Services, client, make_key, wait_job

POSTGRES_NIGHTLY = True  # routes over the store: CI runs them on SQLite (conftest)

KEY_TTL = 2.0  # seconds a verified key is trusted by an API process (PDEANIM_KEY_CACHE_SECONDS)
JOB_NICE = 7
CYCLIC = {"mode": "eel", "frames": 12, "n_curves": 21, "points": 24, "modes": 4}


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"),
                                {"PDEANIM_KEY_CACHE_SECONDS": str(KEY_TTL),
                                 "PDEANIM_JOB_NICE": str(JOB_NICE)},
                                server_args=("--workers", "2"))


@pytest.fixture(scope="module")
def clip(api, services, data_dir) -> dict:
    mesh = api.post("/v1/meshes", files={"file": ("fish_eel.obj", (data_dir / "fish_eel.obj").read_bytes())})
    assert mesh.status_code == 201, mesh.text
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh.json()["id"], "params": CYCLIC})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"])
    assert job["state"] == "succeeded", (job, services.logs())
    return api.get(f"/v1/clips/{job['result']['clip_id']}").json()


def library_frame(api: httpx.Client, clip: dict, t: float) -> bytes:
    """The frame GLB computed here by the library from the clip's parts downloaded over HTTP."""
    from pdeanim.clip import load_clip
    from pdeanim.gltf.write import FrameGlb

    coefficients = api.get(f"/v1/clips/{clip['id']}/coefficients").content
    topology = api.get(f"/v1/meshes/{clip['mesh_id']}/topology", params={"clip_id": clip["id"]}).content
    c = load_clip(topology, coefficients)
    return FrameGlb(c.faces, c.n_vertices)(c.evaluate(t))


def test_cached_and_uncached_frames_are_byte_identical(api, clip, services):
    url = f"/v1/clips/{clip['id']}/frame"
    for t in (0.0, 0.37, 0.9):
        expected = library_frame(api, clip, t)
        # one keep-alive connection stays on one API process: the first answer is computed, the rest come
        # from that process's encoded-frame cache; fresh connections reach the other process too
        with client(services, None) as fresh:
            first = [fresh.get(url, params={"t": t}, headers=api.headers) for _ in range(4)]
        others = [httpx.get(services.url + url, params={"t": repr(t) + "0"}, headers=api.headers, timeout=60)
                  for _ in range(4)]
        for r in first + others:
            assert r.status_code == 200, r.text
            assert r.headers["content-type"] == "model/gltf-binary"
            assert r.content == expected
        assert len({r.headers["etag"] for r in first + others}) == 1
        again = api.get(url, params={"t": t}, headers={"If-None-Match": first[0].headers["etag"]})
        assert again.status_code == 304 and again.content == b""


def revoke(services: Services, key: str) -> None:
    """Revoke ``key`` the way the store records it: set ``revoked_at`` on its row."""
    from pdeanim_service.store.context import Store
    from pdeanim_service.store.models import ApiKey
    from pdeanim_service.store.tenants import hash_key

    store = Store.open(services.backend.settings())
    try:
        with store.sessions() as session:
            session.execute(update(ApiKey).where(ApiKey.key_hash == hash_key(key))
                            .values(revoked_at=time.time()))
            session.commit()
    finally:
        store.close()


def test_a_revoked_key_stops_working_within_the_cache_ttl(services, clip):
    key = make_key(services.backend, "alice")
    url, headers = f"{services.url}/v1/clips/{clip['id']}/frame", {"Authorization": f"Bearer {key}"}

    def status() -> int:  # a new connection each time, so both API processes answer over the loop
        return httpx.get(url, params={"t": 0.5}, headers=headers, timeout=60).status_code

    assert [status() for _ in range(6)] == [200] * 6  # now cached as valid in the processes that answered
    revoke(services, key)
    revoked_at = time.monotonic()
    # until the TTL has passed a process may still trust its cached verification; then none may
    deadline = revoked_at + KEY_TTL + 60  # generous: requests are slow on a loaded machine
    seen_401 = None
    while time.monotonic() < deadline:
        code = status()
        assert code in (200, 401), code
        if code == 401 and seen_401 is None:
            seen_401 = time.monotonic()
        if time.monotonic() > revoked_at + KEY_TTL and code == 401 and seen_401 is not None:
            break
    assert seen_401 is not None, "the revoked key was still accepted past the deadline"
    # the TTL is now over for every process: every request must be refused
    assert time.monotonic() - revoked_at > KEY_TTL
    assert [status() for _ in range(6)] == [401] * 6


def _processes() -> dict[int, tuple[int, int, str]]:
    """pid -> (parent pid, nice, command line) of every process we can read."""
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) "
        out[int(entry.name)] = (int(fields[1]), int(fields[16]), cmd)
    return out


def _descendants(root: int, table: dict[int, tuple[int, int, str]]) -> list[int]:
    children: dict[int, list[int]] = {}
    for pid, (ppid, _, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    out, todo = [], [root]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _policy(pid: int) -> int | None:
    """The scheduling policy of ``pid`` (field 41 of /proc/PID/stat: 0 normal, 5 SCHED_IDLE), or None."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat[stat.rindex(")") + 2:].split()[38])


def test_the_job_process_runs_niced_under_sched_idle(api, services, data_dir):
    if not Path("/proc/self/stat").exists():
        missing("reads process priorities from /proc (Linux)")
    worker = services.workers[0].pid
    base = _processes()[worker][1]  # the worker's own priority (the test run itself may be niced)
    expected = min(19, base + JOB_NICE)
    mesh = api.post("/v1/meshes", files={"file": ("spot.obj", (data_dir / "spot.obj").read_bytes())}).json()
    job = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                     "params": {"frames": 40, "target_tets": 1500}}).json()
    seen: dict[int, int] = {}  # job process -> its nice value (set as the process starts its stage)
    policies: dict[int, int | None] = {}
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and expected not in seen.values():
        table = _processes()
        for pid in _descendants(worker, table):
            ppid, nice, _ = table[pid]
            if "forkserver" in table.get(ppid, (0, 0, ""))[2]:  # a job process (forked by the forkserver)
                seen[pid] = nice
                if nice == expected:
                    policies[pid] = _policy(pid)
        if api.get(f"/v1/jobs/{job['id']}").json()["state"] in ("succeeded", "failed"):
            break
        time.sleep(0.05)
    assert expected in seen.values(), f"job processes seen: {seen} ({services.logs()})"
    assert set(policies.values()) <= {getattr(os, "SCHED_IDLE", 5), None} and any(policies.values()), policies
    assert _processes()[worker][1] == base  # the worker itself keeps its priority
    assert _policy(worker) == 0
    assert wait_job(api, job["id"], 300)["state"] == "succeeded"


def test_lower_priority_joins_a_cgroup_v1_cpu_group(tmp_path):
    # a stand-in for /sys/fs/cgroup/cpu (real files): the group is made, its share set, this pid written
    (tmp_path / "cgroup.procs").write_text("")
    assert lower_priority(0, 128, cgroup_root=tmp_path) == str(tmp_path / "pdeanim-jobs")
    assert (tmp_path / "pdeanim-jobs" / "cpu.shares").read_text() == "128"
    assert (tmp_path / "pdeanim-jobs" / "cgroup.procs").read_text() == str(os.getpid())
    assert lower_priority(0, 0, cgroup_root=tmp_path) is None  # shares 0: no cgroup
    assert lower_priority(0, 128, cgroup_root=tmp_path / "missing") is None  # not available: nice alone


def test_body_cache_is_a_bounded_lru():
    cache = BodyCache(max_bytes=1000)
    bodies = {k: bytes([k]) * 200 for k in range(6)}
    for k in range(4):
        cache.put(k, bodies[k])
    assert cache.get(0) == bodies[0]  # 0 is now the most recently used
    cache.put(4, bodies[4])
    cache.put(5, bodies[5])  # 1200 bytes > 1000: the least recently used (1) goes
    assert cache.get(1) is None
    assert [cache.get(k) for k in (0, 2, 3, 4, 5)] == [bodies[k] for k in (0, 2, 3, 4, 5)]
    assert cache.size == 1000 and len(cache) == 5
    cache.put("big", bytes(300))  # over a quarter of the budget: not kept
    assert cache.get("big") is None and cache.size == 1000
    assert cache.hits == 6 and cache.misses == 2
    assert BodyCache(0).get(0) is None
