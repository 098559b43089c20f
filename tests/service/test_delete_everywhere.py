"""Deletes take effect in every API process: two real ``pdeanim serve`` processes on one database (one HTTP
process each, so each keeps its own clip and frame caches), clips warmed in the second, then deleted through
the first while the second is under load. Every request sent to the second after the DELETE answered gets
404: frames, animations, coefficients, metadata. The processes warm their kernels before taking requests.
Also the clip cache's one load per clip, and its gone ids."""

from __future__ import annotations

import random
import threading
import time
from pathlib import Path

import httpx
import pytest

from pdeanim.clip import load_clip_file
from pdeanim.gltf.write import FrameGlb
from pdeanim_service.api.cache import CachedClip, ClipCache

from .harness import Services, make_key, wait_job

DATA = Path(__file__).resolve().parents[1] / "data"
CYCLIC = {"mode": "eel", "frames": 12, "n_curves": 21, "points": 24, "modes": 4}
FIXTURE = Path(__file__).resolve().parents[2] / "service" / "api" / "warmup" / "fit-rigid-chord.clip"


@pytest.fixture
def two_apis(backend, tmp_path):
    """API process A (with a job worker) and API process B on the same backend, one HTTP process each."""
    a = Services(backend, tmp_path / "a")
    b = Services(backend, tmp_path / "b")
    try:
        a.start_server("--workers", "1")
        a.start_worker()
        b.start_server("--workers", "1", "--no-migrate")
        yield a, b
    finally:
        b.stop()
        a.stop()


def _clip(api: httpx.Client, mesh_id: str) -> str:
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh_id, "params": CYCLIC})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"], timeout=240)
    assert job["state"] == "succeeded", job
    return job["result"]["clip_id"]


class Load:
    """Threads sending frame, animation, coefficients and metadata requests for ``clip_ids`` to one server,
    each answer recorded with the monotonic time its request was sent."""

    PATHS = ("frame", "animation", "coefficients", "")

    def __init__(self, url: str, key: str, clip_ids: list[str], threads: int = 4) -> None:
        self.url, self.key, self.clip_ids = url, key, clip_ids
        self.seen: list[tuple[float, str, str, int, float]] = []  # (sent, clip, path, status, answered)
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=self._run, args=(i,), daemon=True) for i in range(threads)]

    def _run(self, seed: int) -> None:
        rng = random.Random(seed)
        with httpx.Client(base_url=self.url, headers={"Authorization": f"Bearer {self.key}"},
                          timeout=60) as api:
            while not self.stop.is_set():
                clip, path = rng.choice(self.clip_ids), rng.choice(self.PATHS)
                params = {"t": rng.random()} if path == "frame" else (
                    {"fps": rng.choice([10, 12])} if path == "animation" else {})
                sent = time.monotonic()
                status = api.get(f"/v1/clips/{clip}{'/' + path if path else ''}", params=params).status_code
                self.seen.append((sent, clip, path, status, time.monotonic()))

    def __enter__(self) -> Load:
        for t in self.threads:
            t.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(60)

    def after(self, since: float, clip: str) -> list[tuple[str, int]]:
        """(path, status) of the requests for ``clip`` sent after ``since``."""
        return [(p, s) for sent, c, p, s, _ in list(self.seen) if c == clip and sent > since]

    def wait_for(self, since: float, clip: str, count: int, timeout: float = 120) -> None:
        """Wait until ``count`` requests of every path were sent for ``clip`` after ``since``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            paths = [p for p, _ in self.after(since, clip)]
            if all(paths.count(p) >= count for p in self.PATHS):
                return
            time.sleep(0.05)
        raise TimeoutError(f"fewer than {count} requests per path for {clip} within {timeout} s")


def test_a_delete_through_one_process_is_seen_by_the_other_under_load(two_apis, backend):
    a, b = two_apis
    key = make_key(backend, "deleter")
    headers = {"Authorization": f"Bearer {key}"}
    with httpx.Client(base_url=a.url, headers=headers, timeout=60) as api_a, \
            httpx.Client(base_url=b.url, headers=headers, timeout=60) as api_b:
        mesh = api_a.post("/v1/meshes", files={"file": ("fish.obj", (DATA / "fish_eel.obj").read_bytes())})
        assert mesh.status_code == 201, mesh.text
        clip, kept, by_mesh = (_clip(api_a, mesh.json()["id"]) for _ in range(3))
        fish2 = (DATA / "fish_eel.obj").read_bytes() + b"\n# another file\n"
        other_mesh = api_a.post("/v1/meshes", files={"file": ("fish2.obj", fish2)})
        assert other_mesh.status_code == 201, other_mesh.text
        in_mesh = _clip(api_a, other_mesh.json()["id"])
        ids = [clip, kept, by_mesh, in_mesh]
        for c in ids:  # B holds every clip decoded, with frames and animations in its body cache
            assert api_b.get(f"/v1/clips/{c}/frame", params={"t": 0.5}).status_code == 200
            assert api_b.get(f"/v1/clips/{c}/animation", params={"fps": 10}).status_code == 200
        with Load(b.url, key, ids) as load:
            load.wait_for(0.0, clip, 3)
            delete_sent = time.monotonic()
            r = api_a.delete(f"/v1/clips/{clip}")
            assert r.status_code == 200, r.text
            deleted_at = time.monotonic()
            r = api_a.delete(f"/v1/meshes/{other_mesh.json()['id']}")
            assert r.status_code == 200 and r.json()["clips"] == 1, r.text
            mesh_deleted_at = time.monotonic()
            load.wait_for(mesh_deleted_at, clip, 10)
            load.wait_for(mesh_deleted_at, in_mesh, 10)
        before = [s for _, c, _, s, answered in load.seen if c == clip and answered < delete_sent]
        served = [(p, s) for p, s in load.after(deleted_at, clip) if s != 404]
        served += [(p, s) for p, s in load.after(mesh_deleted_at, in_mesh) if s != 404]
        assert not served, f"B answered deleted clips after DELETE returned: {served[:10]}\n{b.logs()}"
        assert all(s == 200 for _, s in load.after(mesh_deleted_at, kept)), "the other clips stay served"
        assert before and set(before) == {200}, "B served the clip before the DELETE"
        assert api_b.get(f"/v1/clips/{by_mesh}/frame", params={"t": 0.25}).status_code == 200
    log = b.log("server")  # warm start: the kernels were loaded before the process took requests
    assert "warm start: clip modules and kernels ready" in log, log[-3000:]
    assert log.index("warm start: clip modules") < log.index("Application startup complete"), log[-3000:]


def test_the_clip_cache_loads_a_clip_once_for_all_waiters_and_never_keeps_a_gone_one():
    cache, loads, started, release = ClipCache(8), [], threading.Event(), threading.Event()
    clip = load_clip_file(FIXTURE)

    def load() -> CachedClip:
        loads.append(1)
        started.set()
        assert release.wait(30)
        return CachedClip("t", "k", "topo", clip, FrameGlb(clip.faces, clip.n_vertices))

    got: list[CachedClip] = []
    threads = [threading.Thread(target=lambda: got.append(cache.get("c1", load))) for _ in range(8)]
    for t in threads:
        t.start()
    assert started.wait(30)
    assert cache.tracked() == ["c1"]  # a load in flight is checked for deletion too
    cache.forget(["c1"])  # deleted while loading: the load finishes but is not kept
    release.set()
    for t in threads:
        t.join(30)
    assert len(loads) == 1 and len(got) == 8 and len({id(g) for g in got}) == 1
    assert cache.is_gone("c1") and cache.peek("c1") is None and cache.tracked() == []


def test_the_bundled_warm_up_clips_load_and_warm_without_a_warning(caplog):
    from pdeanim_service.api.warmup import warm_clip_routes, warmup_clips

    assert len(warmup_clips()) >= 6
    for path in warmup_clips():
        assert load_clip_file(path).n_vertices > 0
    with caplog.at_level("WARNING", logger="pdeanim.api"):
        warm_clip_routes()
    assert not [r for r in caplog.records if r.levelname == "WARNING"], caplog.text
