"""The end-to-end demo behind ``pdeanim demo``: start the API and a worker on the embedded default, upload
a mesh, simulate and fit it, download an in-between frame and the animation, print sizes, errors, timings."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path

import httpx

from .launcher import Launcher
from .settings import Settings
from .store.tenants import issue_key

SAMPLE_MESH = Path(str(files("pdeanim.data") / "spot.obj"))  # package data: the demo runs without a checkout
SCENE = {"frames": 60, "target_tets": 1500}
FIT = {"target_rel_rms": 0.002}


@dataclass
class StageClock:
    """Wall time per stage name (the first word of the job's stage text) seen while polling."""

    current: str | None = None
    since: float = 0.0
    seconds: dict[str, float] = field(default_factory=dict)

    def see(self, stage: str, now: float) -> None:
        """Account the time since the last change to the previous stage."""
        name = (stage.split() or ["?"])[0].rstrip(":")
        if name != self.current:
            self.stop(now)
            self.current, self.since = name, now

    def stop(self, now: float) -> None:
        """Close the running stage."""
        if self.current is not None:
            self.seconds[self.current] = self.seconds.get(self.current, 0.0) + now - self.since
            self.current = None


def _bar(fraction: float, stage: str, width: int = 30) -> str:
    done = int(round(width * min(max(fraction, 0.0), 1.0)))
    return f"\r  [{'#' * done}{'.' * (width - done)}] {100 * fraction:5.1f}%  {stage[:50]:<50}"


class DemoServices(Launcher):
    """The API server (``api_processes`` uvicorn processes) and one worker on ``data_dir``."""

    def __init__(self, data_dir: Path, api_processes: int = 1):
        super().__init__(data_dir / "logs", env={**os.environ, "PDEANIM_DATA_DIR": str(data_dir)})
        self.api_processes = api_processes

    def start(self) -> str:
        """Start both processes and wait for /healthz; returns the base URL."""
        url = self.start_server("--workers", str(self.api_processes))
        self.start_worker("--log-level", "WARNING")
        return url


def _follow(api: httpx.Client, job_id: str) -> tuple[dict, dict[str, float]]:
    """Poll the job, drawing a progress bar (one line per stage when not on a terminal)."""
    clock, tty, shown = StageClock(), sys.stdout.isatty(), None
    while True:
        job = api.get(f"/v1/jobs/{job_id}").json()
        now = time.monotonic()
        if job["state"] == "running":
            clock.see(job["stage"], now)
        done = job["state"] in ("succeeded", "failed")
        if tty:
            print(_bar(job["progress"], job["stage"]), end="\n" if done else "", flush=True)
        elif done or clock.current != shown:
            shown = clock.current
            print(_bar(job["progress"], job["stage"]).lstrip("\r").rstrip(), flush=True)
        if done:
            clock.stop(now)
            return job, clock.seconds
        time.sleep(0.2)


def _timed(fn):  # noqa: ANN001, ANN202
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def run_demo(mesh: Path | None, out_dir: Path, data_dir: Path | None, keep: bool) -> int:
    """Run the demo end to end; returns the exit code."""
    mesh = Path(mesh or SAMPLE_MESH)
    temp = data_dir is None
    data_dir = Path(data_dir or tempfile.mkdtemp(prefix="pdeanim-demo-"))
    data_dir.mkdir(parents=True, exist_ok=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    print(f"pdeanim demo: data in {data_dir}, outputs in {out_dir}")
    services = DemoServices(data_dir)
    try:
        key = issue_key(Settings(data_dir=data_dir), "demo")
        url, t_start = _timed(services.start)
        print(f"  service and worker up at {url} ({t_start:.1f} s)")
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=120) as api:
            return _exercise(api, mesh, out_dir)
    finally:
        services.stop()
        print("  stopped the service and the worker")
        if temp and not keep:
            shutil.rmtree(data_dir, ignore_errors=True)


def _check(r: httpx.Response, what: str) -> httpx.Response:
    if r.status_code >= 400:
        raise RuntimeError(f"{what} failed: HTTP {r.status_code} {r.text[:500]}")
    return r


def _exercise(api: httpx.Client, mesh_path: Path, out_dir: Path) -> int:
    r, t_up = _timed(
        lambda: _check(
            api.post("/v1/meshes", files={"file": (mesh_path.name, mesh_path.read_bytes())}), "mesh upload"
        )
    )
    mesh = r.json()
    print(
        f"  uploaded {mesh_path.name}: {mesh['vertices']} vertices, {mesh['faces']} faces, "
        f"watertight={mesh['stats'].get('watertight')} ({t_up * 1000:.0f} ms)"
    )
    job = _check(
        api.post(
            "/v1/jobs",
            json={"kind": "simulate", "mesh_id": mesh["id"], "params": SCENE, "then_fit": True, "fit": FIT},
        ),
        "job submission",
    ).json()
    print(
        f"  job {job['id']}: simulate {SCENE['frames']} frames, then fit to rel. RMS {FIT['target_rel_rms']}"
    )
    started = time.monotonic()
    job, stages = _follow(api, job["id"])
    total = time.monotonic() - started
    if job["state"] != "succeeded":
        print(f"  job failed: {job['error']}")
        return 1
    clip = api.get(f"/v1/clips/{job['result']['clip_id']}").json()
    poses = _check(api.get(f"/v1/poses/{job['result']['poses_id']}"), "poses download").content
    coef = _check(api.get(f"/v1/clips/{clip['id']}/coefficients"), "coefficients").content
    topo = _check(
        api.get(f"/v1/meshes/{mesh['id']}/topology", params={"clip_id": clip["id"]}), "topology"
    ).content
    frame, t_frame = _timed(
        lambda: _check(api.get(f"/v1/clips/{clip['id']}/frame", params={"t": 0.5}), "frame")
    )
    lat = [
        _timed(lambda i=i: api.get(f"/v1/clips/{clip['id']}/frame", params={"t": (i + 0.5) / 20}))[1]
        for i in range(20)
    ]
    anim, t_anim = _timed(
        lambda: _check(api.get(f"/v1/clips/{clip['id']}/animation", params={"fps": 30}), "animation")
    )
    (out_dir / "frame_t0.5.glb").write_bytes(frame.content)
    (out_dir / "animation.glb").write_bytes(anim.content)
    (out_dir / "poses.npz").write_bytes(poses)
    raw = clip["frames"] * mesh["vertices"] * 3 * 4
    err = clip["errors"]
    print(f"  sizes:  raw float32 frames {raw:,} B | poses.npz {len(poses):,} B | topology {len(topo):,} B "
          f"(once per mesh) | "
          f"coefficients {len(coef):,} B ({len(coef) / raw:.2%} of raw) | frame GLB {len(frame.content):,} B "
          f"| animation GLB {len(anim.content):,} B")
    print(f"  fit:    {clip['segments']} time segments, {clip['curves']} curves; "
          f"error rms {err.get('rms', 0):.4g}, max {err.get('max', 0):.4g}, "
          f"rel. rms {err.get('rel_rms', 0):.3%} of the bbox diagonal")
    by_stage = ", ".join(f"{k} {v:.1f} s" for k, v in stages.items())
    print(f"  timing: upload {t_up:.2f} s | job {total:.1f} s ({by_stage}) | "
          f"first frame {t_frame * 1000:.0f} ms, cached frames median {sorted(lat)[10] * 1000:.1f} ms | "
          f"animation {t_anim * 1000:.0f} ms")
    print(f"  wrote {out_dir / 'frame_t0.5.glb'}, {out_dir / 'animation.glb'}, {out_dir / 'poses.npz'}")
    return 0
