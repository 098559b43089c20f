"""Viewer playback of a 50k-vertex clip in headless Chromium (software WebGL, SwiftShader): frames per second
and JavaScript milliseconds per frame, GPU (vertex shader) against CPU evaluation.

    .venv/bin/python benchmarks/viewer_playback.py [--vertices 50000] [--runs 5] [--seconds 4]

Starts the API server and a worker on a temporary data directory, makes the clip as the demo does (spot,
here refined to ``--vertices`` vertices, simulated and fitted), opens ``/viewer`` in Chromium and lets it
play.
Figures are medians over ``--runs`` windows of ``--seconds``; the load average is printed because the
machine may be shared. Needs script/setup's chromium and tests/browser/node_modules (puppeteer-core).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from service_frames import SPOT, check, wait_job  # noqa: E402

from pdeanim_service.demo import FIT, DemoServices  # noqa: E402
from pdeanim_service.settings import Settings  # noqa: E402
from pdeanim_service.store.tenants import issue_key  # noqa: E402


def spot_refined(target: int) -> bytes:
    """Spot subdivided until the next split would pass ``target`` vertices, then its largest faces split at
    their centroid (1 -> 3, closed and manifold) up to exactly ``target`` vertices; as OBJ bytes."""
    import trimesh

    from pdeanim.mesh.io import load_mesh

    m = load_mesh(SPOT)
    t = trimesh.Trimesh(m.vertices, m.faces, process=False)
    while len(t.vertices) + len(t.edges_unique) <= target:
        t = t.subdivide()
    k = target - len(t.vertices)
    if not 0 <= k <= len(t.faces):
        raise ValueError(f"cannot refine spot to {target} vertices")
    pick = np.argsort(-t.area_faces, kind="stable")[:k]
    a, b, c = t.faces[pick].T
    new = len(t.vertices) + np.arange(k)
    faces = np.vstack([np.delete(t.faces, pick, axis=0), np.column_stack([a, b, new]),
                       np.column_stack([b, c, new]), np.column_stack([c, a, new])])
    buf = io.StringIO()
    np.savetxt(buf, np.vstack([t.vertices, t.triangles_center[pick]]), fmt="v %.6f %.6f %.6f")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


def simulate_and_fit(api: httpx.Client, name: str, data: bytes, scene: dict, fit: dict) -> tuple[dict, float]:
    """Upload the mesh, simulate ``scene`` and fit the poses with ``fit`` in one job; (job, seconds)."""
    mesh = check(api.post("/v1/meshes", files={"file": (name, data)}))
    job = check(api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"], "params": scene,
                                           "then_fit": True, "fit": fit}))
    start = time.monotonic()
    return wait_job(api, job["id"], 3 * 3600), time.monotonic() - start


def reuse_clip(api: httpx.Client, data: Path) -> dict | None:
    """The clip a previous run left in ``data`` (same tenant: the demo key's), or None."""
    record = data / "clip.json"
    if not record.exists():
        return None
    r = api.get(f"/v1/clips/{json.loads(record.read_text())['clip_id']}")
    return r.json() if r.status_code == 200 else None


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> int:
    """Make the clip, play it in both modes, print the medians."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=int, default=50_000)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--width", type=int, default=1280, help="page width (the 3D view is this minus 308 px)")
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--modes", nargs="*", default=["gpu", "cpu", "static"],
                    help="gpu, cpu, and static (the mesh drawn every frame without animating: the drawing "
                    "cost alone)")
    ap.add_argument("--no-antialias", action="store_true",
                    help="open the viewer with #aa=0 (no multisampling)")
    ap.add_argument("--data-dir", type=Path, help="keep the service data here and reuse its clip on a rerun "
                    "(default: a temporary directory)")
    args = ap.parse_args()
    print(f"load average before: {load()}")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    with tempfile.TemporaryDirectory(prefix="pdeanim-bench-") as tmp:
        data = args.data_dir or Path(tmp)
        data.mkdir(parents=True, exist_ok=True)
        services = DemoServices(data)
        try:
            key, url = issue_key(Settings(data_dir=data), "demo"), services.start()
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=600) as api:
                clip = reuse_clip(api, data)
                if clip is None or clip["info"].get("n_vertices") != args.vertices:
                    job, total = simulate_and_fit(api, "spot_50k.obj", spot_refined(args.vertices),
                                                  {"frames": args.frames, "target_tets": 1500}, FIT)
                    clip = api.get(f"/v1/clips/{job['result']['clip_id']}").json()
                    (data / "clip.json").write_text(json.dumps({"clip_id": clip["id"]}))
                    print(f"simulate + fit: {total:.0f} s")
            print(f"clip: {clip['kind']}, {clip['info'].get('n_vertices')} vertices, "
                  f"{clip['frames']} frames, {clip['segments']} segments, {clip['curves']} curves")
            out_path = Path(tmp) / "playback.json"
            aa = "&aa=0" if args.no_antialias else ""
            job_arg = {"url": f"{url}/viewer#clip={clip['id']}&key={key}{aa}", "modes": args.modes,
                       "runs": args.runs, "seconds": args.seconds, "width": args.width, "height": args.height,
                       "out": str(out_path)}
            subprocess.run(["node", str(ROOT / "benchmarks" / "viewer_playback.mjs"), json.dumps(job_arg)],
                           check=True, cwd=ROOT, timeout=1800)
            res = json.loads(out_path.read_text())
        finally:
            services.stop()
    print(f"Chromium WebGL renderer: {res['renderer']}; canvas {res['canvas'][0]}x{res['canvas'][1]}"
          f"{' without' if args.no_antialias else ' with'} multisampling; {res['vertices']} vertices")
    print(f"{'mode':<6} {'fps (median of runs)':>20} {'JS ms/frame median':>19} {'JS ms/frame p95':>16}"
          "  runs")
    for mode, runs in res["runs"].items():
        fps = statistics.median(r["fps"] for r in runs)
        med = statistics.median(r["jsMsMedian"] for r in runs)
        p95 = statistics.median(r["jsMsP95"] for r in runs)
        print(f"{mode:<5} {fps:>20.1f} {med:>19.3f} {p95:>16.3f}  "
              + ", ".join(f"{r['fps']:.1f} fps/{r['jsMsMedian']:.2f} ms" for r in runs))
    print(f"load average after: {load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
