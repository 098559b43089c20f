"""Frame-serving benchmark (loopback only): ``wrk -t2 -c16`` against the service as a user starts it
(``pdeanim serve --with-workers 1``, the embedded default) and, in the same run, against a bare FastAPI
app (two uvicorn processes, ``bare_frames_app.py``) answering a body of the same size; requests/s, p50,
p99 and the ratio to the bare app, medians of several rounds, for the clip shapes users make:

- ``captured``: a captured, noisy sequence (samba, its first 60 frames, two copies side by side: 19,942
  vertices), uploaded as poses and fitted at rel. RMS 3e-3;
- ``simulated``: ``simulate`` of the repository's spot mesh (2,930 vertices, 120 frames), fitted at 3e-3;
- ``long``: many frames (pdance, 201 frames x 7,061 vertices), fitted at 3e-3;
- ``generated``: the smooth generated sway of a 20k-vertex spot (the benchmark's clip before 2026-12-02).

For each shape: the API is restarted and wrk runs at once for ``--fresh-seconds`` (a fresh process: its
first requests), then the warm rounds; the in-process parts (load, evaluate, normals, frame GLB) and the
clip's segments and curves are printed with the table. Optionally (not ``--skip-busy``) the first shape
again with two job workers busy, and (``--animation``) the animation GLB time of the first shape's clip.

    .venv/bin/python benchmarks/service_frames.py [--shapes captured,simulated,long] [--rounds 3]
        [--seconds 8] [--fresh-seconds 4] [--connections 16] [--sequences DIR]

Needs ``wrk`` (Debian package, installed by ``script/setup``). Each request asks for a random t drawn per
request by a wrk Lua script: ``player`` t on the 30 fps grid of the clip (what a player at a fixed frame
rate asks for; repeats hit the encoded-frame cache) and ``continuous`` t (uniform in [0, 1]: every request
evaluates a new frame). Starts and stops everything itself in a temporary data directory.
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pdeanim_service.cli import CONSOLE  # noqa: E402
from pdeanim_service.settings import Settings  # noqa: E402
from pdeanim_service.store.tenants import issue_key  # noqa: E402

SPOT = ROOT / "tests" / "data" / "spot.obj"
SEQUENCES = Path("/work/shared/data/sequences")  # research sequences: never shipped with the project
TARGET = 3e-3  # rel. RMS of the fits
FPS, SECONDS_OF_CLIP = 30, 2.0

LUA = r"""
local path = os.getenv("BENCH_PATH")
local grid = tonumber(os.getenv("BENCH_GRID"))
local auth = os.getenv("BENCH_AUTH")
if auth ~= "" then wrk.headers["Authorization"] = "Bearer " .. auth end
local counter = 0
function setup(thread) counter = counter + 1; thread:set("seed", counter) end
function init(args) math.randomseed(os.time() * 1000 + seed) end
function request()
  local t
  if grid > 0 then t = math.random(0, grid) / grid else t = math.random() end
  return wrk.format("GET", path .. string.format("%.6f", t))
end
function done(summary, latency, requests)
  local s = summary.errors.status + summary.errors.connect + summary.errors.read + summary.errors.write
    + summary.errors.timeout
  io.write(string.format('BENCH {"requests": %d, "us": %d, "p50_us": %d, "p99_us": %d, "errors": %d}\n',
    summary.requests, summary.duration, latency:percentile(50), latency:percentile(99), s))
end
"""


def subdivided_spot(target: int) -> tuple[np.ndarray, np.ndarray]:
    """Spot subdivided once (11,714 vertices), then its largest faces split at their centroid (1 -> 3,
    which keeps the surface closed and manifold) up to ``target`` vertices."""
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
    return np.vstack([t.vertices, t.triangles_center[pick]]), faces


def obj_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A Wavefront OBJ of the mesh."""
    buf = io.StringIO()
    np.savetxt(buf, vertices, fmt="v %.6f %.6f %.6f")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


def swaying_poses(vertices: np.ndarray, faces: np.ndarray, seconds: float = SECONDS_OF_CLIP,
                  fps: int = FPS) -> bytes:
    """POSES.npz of a smooth generated motion (a travelling bend and a breathing scale) over ``seconds``."""
    times = np.arange(int(round(seconds * fps)) + 1) / fps
    v = vertices - vertices.mean(axis=0)
    span = float(np.ptp(v, axis=0).max())
    phase = 2 * np.pi * times[:, None] / seconds
    u = v[:, 0] / span  # along the body
    frames = np.repeat(v[None], len(times), axis=0)
    frames[..., 1] += 0.08 * span * np.sin(phase + 3.0 * u[None])
    frames[..., 2] += 0.05 * span * np.sin(2 * phase - 2.0 * u[None]) * u[None]
    frames *= (1 + 0.03 * np.sin(phase))[..., None]
    buf = io.BytesIO()
    np.savez(buf, vertices=frames.astype(np.float32), faces=faces.astype(np.int32), times=times)
    return buf.getvalue()


def fitted_clip(api: httpx.Client, n_vertices: int, format_version: int | None = None) -> dict:
    """Upload a mesh of about ``n_vertices`` and generated poses, fit them with a job (in the default format,
    or ``format_version``); the clip's metadata."""
    vertices, faces = subdivided_spot(n_vertices)
    obj = obj_bytes(vertices, faces)
    mesh = check(api.post("/v1/meshes", files={"file": (f"spot_{n_vertices}.obj", obj)}))
    poses = check(api.post(f"/v1/meshes/{mesh['id']}/poses",
                           files={"file": ("poses.npz", swaying_poses(vertices, faces))}))
    params = {"target_rel_rms": 0.002, **({"format_version": format_version} if format_version else {})}
    job = check(api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses["id"], "params": params}))
    job = wait_job(api, job["id"], 600)
    return check(api.get(f"/v1/clips/{job['result']['clip_id']}"))


def check(r: httpx.Response) -> dict:
    """The JSON of a successful response; raises with the body otherwise."""
    if r.status_code >= 400:
        raise RuntimeError(f"HTTP {r.status_code} {r.request.url}: {r.text[:300]}")
    return r.json()


def wait_job(api: httpx.Client, job_id: str, seconds: float) -> dict:
    """Poll a job until it ends; raises if it failed or took longer than ``seconds``."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        job = check(api.get(f"/v1/jobs/{job_id}"))
        if job["state"] == "succeeded":
            return job
        if job["state"] == "failed":
            raise RuntimeError(f"job {job_id} failed: {job.get('error')}")
        time.sleep(0.2)
    raise RuntimeError(f"job {job_id} did not finish within {seconds} s")


def free_port() -> int:
    """An unused loopback port."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_http(url: str, proc: subprocess.Popen, seconds: float = 120) -> None:
    """Wait until ``url`` answers (any status); raises if ``proc`` exits first."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{proc.args} exited with {proc.returncode}")
        try:
            httpx.get(url, timeout=2)
            return
        except httpx.HTTPError:
            time.sleep(0.2)
    raise RuntimeError(f"{url} did not answer within {seconds} s")


def wrk(url_path: str, key: str, grid: int, seconds: float, connections: int, script: Path,
        allow_none: bool = False) -> dict:
    """One wrk run (2 threads): requests/s, p50 and p99 in ms; raises on any non-2xx answer or error, and
    when no request finished unless ``allow_none`` (a cold process may answer none in the run: rps 0,
    latencies NaN)."""
    base, path = url_path.split("/", 3)[2], "/" + url_path.split("/", 3)[3]
    env = {**os.environ, "BENCH_PATH": path, "BENCH_GRID": str(grid), "BENCH_AUTH": key}
    cmd = ["wrk", "-t2", f"-c{connections}", f"-d{seconds}s", "--timeout", "10s", "-s", str(script),
           f"http://{base}"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
    line = next(ln for ln in out.splitlines() if ln.startswith("BENCH "))
    r = json.loads(line.removeprefix("BENCH "))
    if allow_none and not r["requests"] and not r["errors"]:
        return {"rps": 0.0, "p50_ms": float("nan"), "p99_ms": float("nan")}
    if r["errors"] or not r["requests"]:
        raise RuntimeError(f"wrk saw {r['errors']} errors / {r['requests']} requests on {url_path}:\n{out}")
    return {"rps": r["requests"] / (r["us"] / 1e6), "p50_ms": r["p50_us"] / 1000,
            "p99_ms": r["p99_us"] / 1000}


class Services:
    """``pdeanim serve --with-workers 1`` (+ extra workers on demand) and the bare app, as child processes."""

    def __init__(self, data_dir: Path, serve_args: list[str], body_bytes: int) -> None:
        self.data_dir, self.serve_args, self.body_bytes = data_dir, serve_args, body_bytes
        self.env = {**os.environ, "PDEANIM_DATA_DIR": str(data_dir)}
        self.log = open(data_dir / "services.log", "ab")  # noqa: SIM115 - closed in stop()
        self.procs: list[subprocess.Popen] = []
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.bare_url = ""
        self.service: subprocess.Popen | None = None
        self.bare: subprocess.Popen | None = None

    def _spawn(self, cmd: list[str], env: dict | None = None) -> subprocess.Popen:
        proc = subprocess.Popen(cmd, env=env or self.env, stdout=self.log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        self.procs.append(proc)
        return proc

    def start_service(self, env: dict[str, str] | None = None) -> float:
        """The service as a user starts it (stopping a running one first: fresh API processes), with extra
        environment ``env``; waits for /healthz and returns the seconds from the start to its first answer."""
        if self.service is not None:
            self._stop_one(self.service)
        started = time.monotonic()
        self.service = self._spawn([*CONSOLE, "serve", "--port", str(self.port), "--with-workers", "1",
                                    *self.serve_args], {**self.env, **(env or {})})
        wait_http(self.url + "/healthz", self.service)
        return time.monotonic() - started

    def start_bare(self, body_bytes: int) -> None:
        """The bare FastAPI app with two uvicorn processes, answering ``body_bytes`` per request (a running
        one is stopped first)."""
        if self.bare is not None:
            self._stop_one(self.bare)
        port = free_port()
        env = {**os.environ, "BARE_BODY_BYTES": str(body_bytes), "PYTHONPATH": str(ROOT)}
        self.bare = self._spawn([sys.executable, "-m", "uvicorn", "benchmarks.bare_frames_app:app", "--port",
                                 str(port), "--workers", "2", "--log-level", "warning", "--no-access-log"],
                                env)
        self.bare_url = f"http://127.0.0.1:{port}"
        wait_http(self.bare_url + "/frame?t=0.5", self.bare)

    def _stop_one(self, proc: subprocess.Popen) -> None:
        """SIGTERM one started process group and wait for it (kill after 30 s)."""
        import signal

        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        self.procs.remove(proc)

    def add_worker(self) -> None:
        """One more job worker (``pdeanim worker``) on the same data directory."""
        self._spawn([*CONSOLE, "worker", "--log-level", "WARNING"])

    def stop(self) -> None:
        """SIGTERM everything started (its process group), kill what is left after 30 s."""
        import signal

        for proc in self.procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self.log.close()


def busy_jobs(api: httpx.Client, poses_id: str, n: int = 10) -> list[str]:
    """Queue ``n`` long jobs alternating simulate (spot, 400 frames, + fit) and fit (the frame clip's poses
    with more segments), so that every worker stays busy."""
    mesh_id = check(api.post("/v1/meshes", files={"file": ("spot.obj", SPOT.read_bytes())}))["id"]
    ids = []
    for i in range(n):
        if i % 2 == 0:
            body = {"kind": "simulate", "mesh_id": mesh_id, "then_fit": True,
                    "params": {"frames": 400, "target_tets": 3000, "seed": i},
                    "fit": {"target_rel_rms": 0.001}}
        else:
            body = {"kind": "fit", "poses_id": poses_id, "params": {"segments": 12 + i}}
        ids.append(check(api.post("/v1/jobs", json=body))["id"])
    return ids


def running(api: httpx.Client, ids: list[str]) -> int:
    """How many of the jobs ``ids`` are running now."""
    return sum(check(api.get(f"/v1/jobs/{i}"))["state"] == "running" for i in ids)


def wait_busy(api: httpx.Client, ids: list[str], seconds: float = 120) -> None:
    """Wait until two of the jobs run (between two jobs a worker is briefly idle); raises past ``seconds``."""
    deadline = time.monotonic() + seconds
    while running(api, ids) < 2:
        states = [check(api.get(f"/v1/jobs/{i}"))["state"] for i in ids]
        if "queued" not in states and states.count("running") < 2:
            raise RuntimeError(f"the busy jobs ran out ({states}): queue longer ones")
        if time.monotonic() > deadline:
            raise RuntimeError(f"the two workers did not run two jobs within {seconds} s ({states})")
        time.sleep(0.3)


def measure(services: Services, key: str, clip: dict, args: argparse.Namespace, script: Path, label: str,
            busy: tuple[httpx.Client, list[str]] | None = None) -> list[dict]:
    """Rounds of (bare, project) wrk runs for each t mode; one row per mode with medians (player t: on the
    clip's frames, a player at the clip's own rate)."""
    grid = max(int(clip.get("frames") or round(SECONDS_OF_CLIP * FPS) + 1) - 1, 1)
    rows = []
    for mode, g in (("player", grid), ("continuous", 0)):
        samples: dict[str, list[dict]] = {"bare": [], "project": []}
        loads = []
        for _ in range(args.rounds):
            if busy is not None:
                wait_busy(*busy)
            samples["bare"].append(wrk(services.bare_url + "/frame?t=", "", g, args.seconds,
                                       args.connections, script))
            samples["project"].append(wrk(f"{services.url}/v1/clips/{clip['id']}/frame?t=", key, g,
                                          args.seconds, args.connections, script))
            loads.append(os.getloadavg()[0])
        med = {who: {k: statistics.median(s[k] for s in runs) for k in runs[0]}
               for who, runs in samples.items()}
        row = {"label": label, "shape": args.shape, "t": mode,
               **{f"{who}_{k}": round(v, 2) for who, m in med.items() for k, v in m.items()},
               "ratio": round(statistics.median(p["rps"] / b["rps"] for p, b in
                                                zip(samples["project"], samples["bare"], strict=True)), 3),
               "load1": round(statistics.median(loads), 2), "rounds": args.rounds}
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def animation_ms(api: httpx.Client, clip_id: str, n: int = 7) -> dict:
    """Wall time of GET /animation at 30 fps over HTTP, median of ``n``: ``first`` at an fps not asked
    before (30 + i * 1e-6, so no cache can answer: evaluate, normals, GLB, content coding, transfer) with
    httpx's Accept-Encoding (gzip, deflate, zstd: zstd is chosen, as by current browsers), ``gzip`` the same
    for a client that accepts only gzip, and ``repeat`` (the first request's fps again: the encoded-body
    cache); the bytes on the wire of the zstd and gzip answers, and of the decoded GLB."""
    times: dict[str, list[float]] = {"first": [], "gzip": [], "repeat": []}
    wire: dict[str, int] = {}
    for i in range(n):
        for name, fps, headers in (("first", FPS + 1e-6 * i, {}), ("gzip", FPS + 1e-6 * (i + n), {
                "Accept-Encoding": "gzip"}), ("repeat", FPS + 1e-6 * i, {})):
            t0 = time.perf_counter()
            r = api.get(f"/v1/clips/{clip_id}/animation", params={"fps": fps}, headers=headers)
            times[name].append((time.perf_counter() - t0) * 1000)
            if r.status_code != 200:
                raise RuntimeError(f"animation: HTTP {r.status_code} {r.text[:200]}")
            wire[name] = int(r.headers.get("content-length", len(r.content)))
            wire["glb"] = len(r.content)
    return {**{f"{k}_median_ms": round(statistics.median(v), 1) for k, v in times.items()},
            **{f"{k}_min_ms": round(min(v), 1) for k, v in times.items() if k != "repeat"},
            "wire_bytes": {"zstd": wire["first"], "gzip": wire["gzip"]}, "glb_bytes": wire["glb"]}


def in_process_ms(data_dir: Path, clip_id: str, which: str, n: int = 5) -> dict:
    """Median wall and CPU times here of what a route computes (``which``), with one BLAS thread as in the
    API process, and of its parts: a frame GLB at a new t (evaluate + normals + GLB; the evaluation and the
    normals alone) or the 30 fps animation GLB (evaluate all frames + normals + quantised, meshopt-compressed
    GLB, the route's default; and each content coding the route may apply to it, with the share of the GLB
    it leaves)."""
    from pdeanim.clip import load_clip
    from pdeanim.gltf.clipexport import clip_animation_glb
    from pdeanim.gltf.normals import FaceNormals
    from pdeanim.gltf.write import FrameGlb
    from pdeanim_service.api import encoding
    from pdeanim_service.api.threads import single_threaded_blas
    from pdeanim_service.settings import Settings
    from pdeanim_service.store.context import Store
    from pdeanim_service.store.models import ClipRecord

    single_threaded_blas()  # as in the API process
    store = Store.open(Settings(data_dir=data_dir))
    try:
        with store.sessions() as session:
            row = session.get(ClipRecord, clip_id)
        topology, coefficients = store.blobs.get(row.topology_key), store.blobs.get(row.coefficients_key)
    finally:
        store.close()
    out: dict = {}
    loads = []
    for _ in range(3):
        t0 = time.perf_counter()
        clip = load_clip(topology, coefficients)
        loads.append((time.perf_counter() - t0) * 1000)
    out["load_ms"] = round(statistics.median(loads), 1)
    if which == "frame":
        writer, normals = FrameGlb(clip.faces, clip.n_vertices), FaceNormals(clip.faces, clip.n_vertices)
        at = np.asarray(clip.evaluate(0.5), np.float32).reshape(-1, 3)
        scratch = np.empty_like(at)
        k = 20 * n
        parts = {"frame": (lambda i: writer(clip.evaluate((i + 0.5) / k)), k),
                 "evaluate": (lambda i: clip.evaluate((i + 0.5) / k), k),
                 "normals": (lambda i: normals(at, out=scratch), k)}
    else:
        glb = clip_animation_glb(clip, FPS, max_frames=10_000)
        parts = {"animation": (lambda i: clip_animation_glb(clip, FPS, max_frames=10_000), n),
                 "zstd": (lambda i: encoding.encode(glb, "zstd"), n),
                 "gzip": (lambda i: encoding.encode(glb, "gzip"), n),
                 "gzip6": (lambda i: gzip.compress(glb, 6, mtime=0), n)}
        out["coded_share"] = {"zstd": round(len(encoding.encode(glb, "zstd")) / len(glb), 3),
                              "gzip": round(len(encoding.encode(glb, "gzip")) / len(glb), 3),
                              "gzip6": round(len(gzip.compress(glb, 6, mtime=0)) / len(glb), 3)}
    for name, (fn, count) in parts.items():
        fn(0)  # warm (numba kernels load from their cache)
        wall, cpu = [], []
        for i in range(count):
            w0, c0 = time.perf_counter(), time.process_time()
            fn(i)
            wall.append((time.perf_counter() - w0) * 1000)
            cpu.append((time.process_time() - c0) * 1000)
        out[f"{name}_ms"] = round(statistics.median(wall), 3)
        out[f"{name}_cpu_ms"] = round(statistics.median(cpu), 3)
    return out


def table(rows: list[dict]) -> str:
    """The performance.md table of the rows."""
    out = ["| clip | process | t per request | `pdeanim serve` requests/s | p50 | p99 | bare app requests/s "
           "| p50 | p99 | ratio | load avg |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        bare = (f"{r['bare_rps']:.0f} | {r['bare_p50_ms']:.1f} ms | {r['bare_p99_ms']:.1f} ms | "
                f"{r['ratio']:.2f}" if "bare_rps" in r else "| | |")
        lat = ("none finished | none finished" if not r["project_rps"] else
               f"{r['project_p50_ms']:.1f} ms | {r['project_p99_ms']:.1f} ms")
        out.append(f"| {r['shape']} | {r['label']} | {r['t']} | {r['project_rps']:.0f} | {lat} | {bare} "
                   f"| {r['load1']:.1f} |")
    return "\n".join(out)


def parts_table(parts: list[dict]) -> str:
    """The in-process costs of each shape's clip (CPU ms, one BLAS thread as in the API)."""
    out = ["| clip | vertices | frames | segments | curves | frame GLB | load the clip | new frame CPU "
           "| evaluate | normals | load avg |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for p in parts:
        out.append(f"| {p['shape']} | {p['vertices']:,} | {p['frames']} | {p['segments']} | {p['curves']} | "
                   f"{p['body_bytes']:,} B | {p['load_ms']:.0f} ms | {p['frame_cpu_ms']:.2f} ms | "
                   f"{p['evaluate_cpu_ms']:.2f} ms | {p['normals_cpu_ms']:.2f} ms | {p['load1']:.1f} |")
    return "\n".join(out)


FRESH = {  # how a fresh process starts: label -> its extra environment
    "fresh": {},
    "fresh, no preload": {"PDEANIM_PRELOAD_CLIPS": "0"},
    "fresh, cold (no warm start)": {"PDEANIM_WARM_START": "false"},
}
FRESH_NAMES = {"fresh": "default", "fresh, no preload": "nopreload", "fresh, cold (no warm start)": "cold"}


def fresh_round(services: Services, key: str, clip: dict, args: argparse.Namespace, script: Path,
                label: str) -> dict:
    """Restart the API (fresh processes, started as FRESH[label] says) and drive it with new frames from its
    first answer on."""
    startup = services.start_service(FRESH[label])
    r = wrk(f"{services.url}/v1/clips/{clip['id']}/frame?t=", key, 0, args.fresh_seconds, args.connections,
            script, allow_none=True)
    row = {"label": f"{label} (up in {startup:.1f} s), first {args.fresh_seconds} s", "shape": args.shape,
           "t": "continuous",
           **{f"project_{k}": round(v, 2) for k, v in r.items()}, "startup_s": round(startup, 2),
           "load1": round(os.getloadavg()[0], 2)}
    print(json.dumps(row), flush=True)
    return row


def make_clip(api: httpx.Client, shape: str, sequences: Path) -> dict:
    """Fit the clip of ``shape`` through the API (see service_frames_shapes.py)."""
    from benchmarks import service_frames_shapes as shapes

    if shape == "simulated":
        return shapes.simulated(api, SPOT, TARGET, check, wait_job)
    if shape == "generated":
        return fitted_clip(api, 20_000)
    vertices, faces = (shapes.captured if shape == "captured" else shapes.long)(sequences)
    return shapes.fit_uploaded(api, shape, vertices, faces, TARGET, obj_bytes, check, wait_job)


def measure_shape(services: Services, api: httpx.Client, key: str, clip: dict, args: argparse.Namespace,
                  script: Path) -> tuple[list[dict], dict]:
    """Fresh-process round, warm rounds and in-process parts of one shape's clip."""
    body = len(check_bytes(api.get(f"/v1/clips/{clip['id']}/frame", params={"t": 0.5})))
    services.start_bare(body)
    labels = [label for label in reversed(FRESH) if FRESH_NAMES[label] in args.fresh.split(",")]
    rows = [fresh_round(services, key, clip, args, script, label) for label in labels]
    if "fresh" not in labels:
        services.start_service()  # the warm rounds run on the default start
    rows += measure(services, key, clip, args, script, "warm")  # the last restart: the default one
    here = in_process_ms(services.data_dir, clip["id"], "frame")
    part = {"shape": args.shape, "vertices": clip["info"]["n_vertices"], "frames": clip["frames"],
            "segments": clip["segments"], "curves": clip["curves"], "body_bytes": body,
            "load1": round(os.getloadavg()[0], 2), **here}
    print(json.dumps(part), flush=True)
    return rows, part


def check_bytes(r: httpx.Response) -> bytes:
    """The body of a successful response; raises with the body otherwise."""
    if r.status_code >= 400:
        raise RuntimeError(f"HTTP {r.status_code} {r.request.url}: {r.text[:300]}")
    return r.content


def main() -> int:
    """Build the clips, start everything, measure each shape, print the tables."""
    from benchmarks.service_frames_shapes import DESCRIPTIONS, SHAPES

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default="captured,simulated,long",
                    help=f"comma-separated clip shapes among {', '.join(SHAPES)}")
    ap.add_argument("--rounds", type=int, default=3, help="wrk runs per configuration (medians are reported)")
    ap.add_argument("--seconds", type=int, default=8, help="duration of one wrk run")
    ap.add_argument("--fresh-seconds", type=int, default=6, help="the wrk run right after a restart")
    ap.add_argument("--fresh", default="cold,nopreload,default",
                    help="fresh-process rounds: cold (no warm start), nopreload (warm start without the "
                         "newest clips), default")
    ap.add_argument("--data-dir", type=Path, default=None,
                    help="keep the service's data here and reuse the clips fitted by an earlier run with the "
                         "same folder (default: a temporary folder)")
    ap.add_argument("--connections", type=int, default=16)
    ap.add_argument("--sequences", type=Path, default=SEQUENCES, help="folder of samba.npz and pdance.npz")
    ap.add_argument("--serve-args", default="", help="extra `pdeanim serve` arguments, e.g. '--workers 1'")
    ap.add_argument("--skip-busy", action="store_true", help="no run with two busy job workers")
    ap.add_argument("--animation", action="store_true", help="also time the first shape's animation GLB")
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # stop the services on the way out
    shape_list = [x.strip() for x in args.shapes.split(",") if x.strip()]
    unknown = sorted(set(shape_list) - set(SHAPES))
    if unknown:
        ap.error(f"unknown shapes {unknown}: choose among {', '.join(SHAPES)}")
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"{started}; load average at start: {os.getloadavg()}, CPUs: {os.cpu_count()}", flush=True)
    rows: list[dict] = []
    parts: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="pdeanim-bench-") as scratch:
        tmp = str(args.data_dir or scratch)
        Path(tmp).mkdir(parents=True, exist_ok=True)
        script = Path(tmp) / "frames.lua"
        script.write_text(LUA)
        services = Services(Path(tmp), args.serve_args.split(), 0)
        try:
            key = issue_key(Settings(data_dir=Path(tmp)), "bench")
            services.start_service()
            with httpx.Client(base_url=services.url, headers={"Authorization": f"Bearer {key}"},
                              timeout=300) as api:
                made = Path(tmp) / "clips.json"  # shape -> clip id, for --data-dir reruns
                known = json.loads(made.read_text()) if made.exists() else {}
                clips = {}
                for shape in shape_list:
                    t0 = time.monotonic()
                    old = known.get(shape) and api.get(f"/v1/clips/{known[shape]}")
                    clips[shape] = old.json() if old and old.status_code == 200 else make_clip(
                        api, shape, args.sequences)
                    known[shape] = clips[shape]["id"]
                    made.write_text(json.dumps(known))
                    c = clips[shape]
                    print(f"{shape} ({DESCRIPTIONS[shape]}): clip {c['id']}, "
                          f"{c['info']['n_vertices']} vertices, {c['frames']} frames, "
                          f"{c['segments']} segments, "
                          f"{c['curves']} curves "
                          f"(made in {time.monotonic() - t0:.0f} s)", flush=True)
                for shape in shape_list:
                    args.shape = shape
                    shape_rows, part = measure_shape(services, api, key, clips[shape], args, script)
                    rows += shape_rows
                    parts.append(part)
                first = clips[shape_list[0]]
                args.shape = shape_list[0]
                if args.animation:
                    print(f"animation GLB over HTTP of the {shape_list[0]} clip, {FPS} fps: "
                          f"{animation_ms(api, first['id'])}", flush=True)
                if not args.skip_busy:
                    services.add_worker()
                    ids = busy_jobs(api, first["poses_id"])
                    wait_busy(api, ids)
                    services.start_bare(len(check_bytes(api.get(f"/v1/clips/{first['id']}/frame",
                                                                 params={"t": 0.5}))))
                    rows += measure(services, key, first, args, script, "warm, 2 job workers busy",
                                    (api, ids))
        finally:
            services.stop()
    print(f"load average at end: {os.getloadavg()}; started {started}, ended "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(table(rows))
    print()
    print(parts_table(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
