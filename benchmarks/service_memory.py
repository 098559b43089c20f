"""Memory of every clip read of the service on a long clip (issue 34): the growth of each process a request
touches (the API process's peak RSS over its RSS before the request; a job process's whole peak), the
response size and the wall time, per route, with the default settings.

The clip is the fit at rel-RMS 3e-3 of ``spot-sim:1000`` (benchmarks/fit_scale_inputs.py: a 34k-vertex spot
simulated for 1,000 frames; made and fitted on the first run, cached in benchmarks/.cache/). It is stored as
a fit job stores its clip (blobs and a clip row) for a mesh uploaded through the API, in a fresh data
directory, and read by ``pdeanim serve --workers 1 --with-workers 1``.

    .venv/bin/python benchmarks/service_memory.py [--repeats 3] [--export-fps 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.fit_scale_inputs import CACHE, ensure_input, parse_long_input  # noqa: E402
from benchmarks.fit_scale_service import descendants, rest_obj  # noqa: E402
from pdeanim_service.launcher import Launcher  # noqa: E402

CONSOLE = [sys.executable, "-m", "pdeanim_service.cli"]
MiB = 1024**2


def status_kib(pid: int, field: str) -> int:
    """A field of /proc/PID/status in KiB (0 if the process is gone)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    for line in text.splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


def reset_peaks(pids: list[int]) -> dict[int, int]:
    """Reset each process's peak RSS to its current RSS (``clear_refs`` 5); their RSS now, in bytes."""
    before = {}
    for pid in pids:
        try:
            Path(f"/proc/{pid}/clear_refs").write_text("5")
        except OSError:
            continue
        before[pid] = status_kib(pid, "VmRSS") * 1024
    return before


class NewProcesses(threading.Thread):
    """The largest peak RSS of the processes below ``root`` that appear after it starts (a job's child)."""

    def __init__(self, root: int, known: set[int]) -> None:
        super().__init__(daemon=True)
        self.root, self.known, self.peak, self.stopped = root, known, 0, threading.Event()

    def run(self) -> None:
        while not self.stopped.wait(0.1):
            for pid in descendants(self.root):
                if pid not in self.known:
                    self.peak = max(self.peak, status_kib(pid, "VmHWM") * 1024)


def measure(server: int, pids: list[int], call) -> dict:  # noqa: ANN001 - call() -> httpx.Response
    """One request: per existing process its peak RSS growth and what it kept, the largest new process's
    peak, the response's size and status, the wall time."""
    before = reset_peaks(pids)
    watcher = NewProcesses(server, set(descendants(server)) | {server})
    watcher.start()
    t0 = time.perf_counter()
    response = call()
    wall = time.perf_counter() - t0
    watcher.stopped.set()
    watcher.join()
    growth = {pid: status_kib(pid, "VmHWM") * 1024 - rss for pid, rss in before.items()}
    kept = {pid: status_kib(pid, "VmRSS") * 1024 - rss for pid, rss in before.items()}
    return {"status": response.status_code, "bytes": len(response.content), "wall": wall,
            "growth": max(growth.values(), default=0), "growth_all": sum(max(g, 0) for g in growth.values()),
            "kept": max(kept.values(), default=0), "new_peak": watcher.peak}


def make_clip(poses: Path, target: float) -> Path:
    """The CLI fit of ``poses`` at ``target`` rel-RMS, cached."""
    out = CACHE / f"{poses.stem}_fit{target:g}.clip"
    if not out.exists():
        subprocess.run([*CONSOLE, "fit", str(poses), "--out", str(out), "--target-rel-rms", repr(target),
                        "--quiet"], check=True)
    return out


def store_clip(data_dir: Path, mesh_id: str, clip: Path) -> str:
    """Store the CLIP file's parts as a fit job stores a clip (blobs and a row) for ``mesh_id``; its id."""
    from pdeanim.clip import read_clip_file
    from pdeanim_service.settings import Settings
    from pdeanim_service.store.context import Store
    from pdeanim_service.store.models import ClipRecord, Mesh

    parts = read_clip_file(clip)
    store = Store.open(Settings(data_dir=data_dir))
    try:
        with store.sessions() as session:
            mesh = session.get(Mesh, mesh_id)
            row = ClipRecord(tenant_id=mesh.tenant_id, mesh_id=mesh_id, poses_id=None, job_id=None,
                             kind="dynamic-pde", topology_key=store.blobs.put(parts.topology),
                             coefficients_key=store.blobs.put(parts.coefficients),
                             topology_id=parts.topology_id, report=parts.report)
            session.add(row)
            session.commit()
            return row.id
    finally:
        store.close()


def routes(api: httpx.Client, clip_id: str, repeats: int, export_fps: float) -> list[tuple[str, object]]:
    """(label, call) of every read, in order; frames at new times each repeat, then a repeated one."""
    url = f"/v1/clips/{clip_id}"
    out: list[tuple[str, object]] = [("GET clip (metadata)", lambda: api.get(url))] * repeats
    out += [("GET coefficients", lambda: api.get(f"{url}/coefficients"))] * repeats
    out += [("GET coefficients (JSON form)",
             lambda: api.get(f"{url}/coefficients", headers={"Accept": "application/json",
                                                              "Accept-Encoding": "identity"}))] * repeats
    out += [("GET topology", lambda: api.get(f"{url}/topology"))] * repeats
    out += [("GET frame, new t", lambda i=i: api.get(f"{url}/frame", params={"t": 0.1 + 0.2 * i}))
            for i in range(repeats)]
    out += [("GET frame, repeated t", lambda: api.get(f"{url}/frame", params={"t": 0.1}))] * repeats
    out += [("GET animation fps 30 (413)", lambda: api.get(f"{url}/animation", params={"fps": 30}))] * repeats
    out += [("GET animation fps 1", lambda i=i: api.get(f"{url}/animation", params={"fps": 1.0 + i / 1000},
                                                         headers={"Accept-Encoding": "identity"}))
            for i in range(repeats)]

    def export() -> httpx.Response:
        job = api.post("/v1/jobs", json={"kind": "export", "clip_id": clip_id, "params": {"fps": export_fps}})
        job.raise_for_status()
        while True:
            state = api.get(f"/v1/jobs/{job.json()['id']}", params={"wait": 10}).json()
            if state["state"] in ("succeeded", "failed", "cancelled"):
                if state["state"] != "succeeded":
                    raise RuntimeError(f"export job {state['state']}: {state.get('error')}")
                return api.get(state["result"]["export_url"], headers={"Accept-Encoding": "identity"})

    if export_fps > 0:
        out += [(f"export job fps {export_fps:g} + download", export)]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--input", default="spot-sim:1000", help="long input (benchmarks/fit_scale_inputs.py)")
    ap.add_argument("--target", type=float, default=3e-3, help="rel-RMS target of the clip's fit")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--export-fps", type=float, default=2.0, help="fps of the export job (0: none)")
    args = ap.parse_args()
    item = parse_long_input(args.input)
    ensure_input(item, CONSOLE, None)
    clip = make_clip(item.path, args.target)
    print(f"# service_memory: {item.name}, clip {clip.name} ({clip.stat().st_size:,} bytes)", flush=True)
    print(f"# start {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())} UTC, load {os.getloadavg()}")
    with tempfile.TemporaryDirectory(prefix="svc-memory-") as tmp:
        data_dir = Path(tmp)
        from pdeanim_service.settings import Settings
        from pdeanim_service.store.tenants import issue_key

        key = issue_key(Settings(data_dir=data_dir), "bench")
        launcher = Launcher(data_dir / "logs", {**os.environ, "PDEANIM_DATA_DIR": str(data_dir),
                                                "PDEANIM_JOB_SCHED_IDLE": "false"})
        launcher.start_server("--workers", "1", "--with-workers", "1", "--log-level", "warning")
        try:
            with httpx.Client(base_url=launcher.url, headers={"Authorization": f"Bearer {key}"},
                              timeout=1800) as api:
                mesh = api.post("/v1/meshes", files={"file": ("spot.obj", rest_obj(item.path))})
                mesh.raise_for_status()
                clip_id = store_clip(data_dir, mesh.json()["id"], clip)
                server = launcher.server.pid
                pids = [server, *descendants(server)]
                idle = {pid: status_kib(pid, "VmRSS") for pid in pids}
                print(f"# processes before the reads: {len(pids)}, RSS MiB "
                      + ", ".join(f"{v / 1024:.0f}" for v in idle.values()))
                rows: dict[str, list[dict]] = {}
                for label, call in routes(api, clip_id, args.repeats, args.export_fps):
                    rows.setdefault(label, []).append(measure(server, pids, call))
                    r = rows[label][-1]
                    print(f"# {label}: HTTP {r['status']}, {r['bytes']:,} bytes, API growth "
                          f"{r['growth_all'] / MiB:.1f} MiB (kept {r['kept'] / MiB:.1f}), job process peak "
                          f"{r['new_peak'] / MiB:.0f} MiB, {r['wall']:.2f} s, load {os.getloadavg()[0]:.1f}",
                          flush=True)
        finally:
            launcher.stop()
    print(f"# end {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())} UTC, load {os.getloadavg()}")
    print("| read | runs | status | response MiB | API growth MiB (median, max) | growth - response MiB "
          "(max) | kept MiB (max) | job process peak MiB | wall s (median) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, runs in rows.items():
        growth = [r["growth_all"] / MiB for r in runs]
        body = max(r["bytes"] for r in runs) / MiB
        over = max((r["growth_all"] - r["bytes"]) / MiB for r in runs)
        wall = statistics.median(r["wall"] for r in runs)
        print(f"| {label} | {len(runs)} | {runs[0]['status']} | {body:.2f} | "
              f"{statistics.median(growth):.1f}, {max(growth):.1f} | {over:.1f} | "
              f"{max(r['kept'] for r in runs) / MiB:.1f} | {max(r['new_peak'] for r in runs) / MiB:.0f} | "
              f"{wall:.2f} |")
    worst = max((r["growth_all"] - r["bytes"]) / MiB for runs in rows.values() for r in runs)
    print(f"- API growth beyond the response, worst read: {worst:.1f} MiB (goal <= 64 MiB): "
          f"{'met' if worst <= 64 else 'NOT met'}")


if __name__ == "__main__":
    main()
