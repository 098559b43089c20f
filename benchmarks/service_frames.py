"""Service benchmark (loopback only): frame requests for a 15k-vertex clip over HTTP with several
concurrent clients (requests/s, p50, p99), the CPU time of one frame GLB (evaluate + normals + GLB) in
process, and the end-to-end time of the demo's job by stage.

    .venv/bin/python benchmarks/service_frames.py [--clients 8] [--seconds 10]

Starts its own API server and worker on a temporary embedded data directory and stops them afterwards.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from service.demo import FIT, SCENE, DemoServices, StageClock  # noqa: E402
from service.settings import Settings  # noqa: E402
from service.store.tenants import issue_key  # noqa: E402

SPOT = ROOT / "tests" / "data" / "spot.obj"


def spot_15k(target: int = 15_000) -> bytes:
    """Spot subdivided once (11,714 vertices), then its largest faces split at their centroid (1 -> 3, which
    keeps the surface closed and manifold) up to ``target`` vertices; as OBJ bytes."""
    import trimesh

    from pdeanim.mesh.io import load_mesh

    m = load_mesh(SPOT)
    t = trimesh.Trimesh(m.vertices, m.faces, process=False).subdivide()
    k = max(target - len(t.vertices), 0)
    pick = np.argsort(-t.area_faces, kind="stable")[:k]
    a, b, c = t.faces[pick].T
    new = len(t.vertices) + np.arange(k)
    faces = np.vstack([np.delete(t.faces, pick, axis=0), np.column_stack([a, b, new]),
                       np.column_stack([b, c, new]), np.column_stack([c, a, new])])
    buf = io.StringIO()
    np.savetxt(buf, np.vstack([t.vertices, t.triangles_center[pick]]), fmt="v %.6f %.6f %.6f")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


def frame_cpu(data_dir: Path, clip_id: str, n: int = 300) -> dict:
    """In-process CPU time of what the frame route computes per request: evaluate at t, normals, GLB."""
    from pdeanim.clip import load_clip
    from pdeanim.gltf.write import FrameGlb
    from service.settings import Settings
    from service.store.context import Store
    from service.store.models import ClipRecord

    store = Store.open(Settings(data_dir=data_dir))
    try:
        with store.sessions() as session:
            row = session.get(ClipRecord, clip_id)
        clip = load_clip(store.blobs.get(row.topology_key), store.blobs.get(row.coefficients_key))
    finally:
        store.close()
    writer = FrameGlb(clip.faces, clip.n_vertices)
    ts = np.random.default_rng(0).random(n)
    parts = {"evaluate": [], "glb": []}
    for t in ts:
        c0 = time.process_time_ns()
        p = np.asarray(clip.evaluate(float(t)))
        c1 = time.process_time_ns()
        writer(p)
        parts["evaluate"].append(c1 - c0)
        parts["glb"].append(time.process_time_ns() - c1)
    total = np.add(parts["evaluate"], parts["glb"]) / 1e6
    out = {f"{k}_median_ms": round(float(np.median(v)) / 1e6, 3) for k, v in parts.items()}
    return {"vertices": clip.n_vertices, "frames": n, **out, "total_median_ms": round(float(np.median(total)), 3),
            "total_p10_ms": round(float(np.percentile(total, 10)), 3)}


def run_job(api: httpx.Client, name: str, data: bytes, scene: dict, fit: dict) -> tuple[dict, dict, float]:
    """Upload, simulate + fit; returns (job, seconds per stage, total seconds)."""
    mesh = api.post("/v1/meshes", files={"file": (name, data)}).json()
    job = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"], "params": scene, "then_fit": True,
                                     "fit": fit}).json()
    clock, start = StageClock(), time.monotonic()
    while job["state"] not in ("succeeded", "failed"):
        time.sleep(0.1)
        job = api.get(f"/v1/jobs/{job['id']}").json()
        if job["state"] == "running":
            clock.see(job["stage"], time.monotonic())
    clock.stop(time.monotonic())
    if job["state"] != "succeeded":
        raise RuntimeError(f"job failed: {job['error']}")
    return job, clock.seconds, time.monotonic() - start


def hammer(url: str, key: str, clip_id: str, clients: int, seconds: float, max_requests: int) -> dict:
    """``clients`` threads requesting frames at distinct t for ``seconds``; latency percentiles and rate."""
    latencies: list[float] = []
    lock, stop = threading.Lock(), time.monotonic() + seconds

    def client(index: int) -> None:
        rng = np.random.default_rng(index)
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=30) as c:
            while time.monotonic() < stop and len(latencies) < max_requests:
                t0 = time.perf_counter()
                r = c.get(f"/v1/clips/{clip_id}/frame", params={"t": float(rng.random())})
                dt = time.perf_counter() - t0
                if r.status_code != 200:
                    raise RuntimeError(f"HTTP {r.status_code}: {r.text[:200]}")
                with lock:
                    latencies.append(dt)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(clients)]
    start = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.monotonic() - start
    lat = np.array(latencies) * 1000
    return {"clients": clients, "requests": len(lat), "seconds": round(wall, 2),
            "requests_per_s": round(len(lat) / wall, 1), "p50_ms": round(float(np.percentile(lat, 50)), 2),
            "p99_ms": round(float(np.percentile(lat, 99)), 2), "mean_ms": round(statistics.fmean(lat), 2)}


def main() -> int:
    """Run both measurements and print them (and as JSON with --json)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--max-requests", type=int, default=20000)
    ap.add_argument("--api-processes", type=int, default=1, help="uvicorn processes of the API (serve --workers)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="pdeanim-bench-") as tmp:
        services = DemoServices(Path(tmp), args.api_processes)
        try:
            key, url = issue_key(Settings(data_dir=Path(tmp)), "bench"), services.start()
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=300) as api:
                job, stages, total = run_job(api, "spot.obj", SPOT.read_bytes(), SCENE, FIT)
                out["demo_job"] = {"total_s": round(total, 2), "stages_s": {k: round(v, 2) for k, v in stages.items()}}
                print(f"demo job (spot, {SCENE['frames']} frames, fit to {FIT}): {total:.1f} s  "
                      + ", ".join(f"{k} {v:.1f} s" for k, v in stages.items()))
                job, stages, total = run_job(api, "spot_15k.obj", spot_15k(), {"frames": 30, "target_tets": 1500},
                                             FIT)
                clip = api.get(f"/v1/clips/{job['result']['clip_id']}").json()
                out["frame_clip"] = {"vertices": clip["info"].get("n_vertices"), "segments": clip["segments"],
                                     "curves": clip["curves"], "job_s": round(total, 2)}
                print(f"frame clip: {out['frame_clip']}")
                out["frame_cpu"] = frame_cpu(Path(tmp), clip["id"])
                print(f"frame CPU in process (evaluate + normals + GLB): {out['frame_cpu']}")
                api.get(f"/v1/clips/{clip['id']}/frame", params={"t": 0.5})  # warm the clip cache
                for clients in sorted({1, args.clients}):
                    res = hammer(url, key, clip["id"], clients, args.seconds, args.max_requests)
                    res["api_processes"] = args.api_processes
                    out.setdefault("frames", []).append(res)
                    print(f"frames over HTTP: {res}")
        finally:
            services.stop()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (shared machine)")
    if args.json:
        print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
