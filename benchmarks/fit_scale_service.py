"""Part (c) of the fit-scale benchmark: one long input as a fit job through the service, as a user runs it
(``pdeanim serve --with-workers N``, the embedded default, in a fresh data directory per run), with 1 and then
2 job workers. First the same upload and submission with the default settings (and, when those refuse the
upload, with the input-size limits alone raised), to show what they refuse; then only the documented settings
that the input needs are raised, and the benchmark prints which."""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

from benchmarks.fit_scale_inputs import input_shape
from pdeanim_service.launcher import Launcher

PRIORITY = {"PDEANIM_JOB_SCHED_IDLE": "false", "PDEANIM_JOB_NICE": "0"}
"""Jobs run at the priority of the CLI's fit (documented settings; the defaults, SCHED_IDLE and nice 10, make
a job crawl on a host whose cores other processes keep busy, as on this shared machine)."""


def raised_settings(poses: Path, frames: int, vertices: int) -> dict[str, str]:
    """The documented settings (environment) that this input needs above their defaults: the upload size, the
    frame and vertex counts, and the job memory limit that the fit's estimate is checked against (its largest
    window task's when the fit runs as window tasks)."""
    from pdeanim.fit import FitOptions
    from pdeanim.fit.budget import fit_memory_bytes, window_task_memory_bytes
    from pdeanim.fit.windowed import windowed_applies
    from pdeanim_service.settings import Settings

    defaults = Settings(data_dir=Path(tempfile.gettempdir()))
    tol = defaults.fit_tolerances()
    env: dict[str, str] = {}
    size = poses.stat().st_size
    if size > defaults.max_upload_bytes:
        env["PDEANIM_MAX_UPLOAD_BYTES"] = str(size + 2**20)
    if frames > defaults.max_frames:
        env["PDEANIM_MAX_FRAMES"] = str(frames)
    if vertices > defaults.max_vertices:
        env["PDEANIM_MAX_VERTICES"] = str(vertices)
    tasks = defaults.fit_window_tasks and windowed_applies(frames, vertices, FitOptions(), tol)
    need = (window_task_memory_bytes if tasks else fit_memory_bytes)(frames, vertices, tol)
    limit = defaults.job_memory_limit()
    if limit and need > limit:
        env["PDEANIM_JOB_MEMORY_BYTES"] = str(need + 2**30)
    return env


def rest_obj(poses: Path) -> bytes:
    """A Wavefront OBJ of the poses' first frame and faces (the mesh the poses are uploaded for)."""
    import io

    with np.load(poses) as data:
        rest, faces = np.asarray(data["vertices"][0]), np.asarray(data["faces"])
    buf = io.StringIO()
    np.savetxt(buf, rest, fmt="v %.7g %.7g %.7g")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


def descendants(root: int) -> list[int]:
    """Process ids below ``root`` (children, grandchildren...), from /proc."""
    parent: dict[int, int] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                stat = Path(entry.path, "stat").read_text()
            except OSError:
                continue
            parent[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    out, frontier = [], [root]
    while frontier:
        kids = [p for p, pp in parent.items() if pp in frontier]
        out += kids
        frontier = kids
    return out


def vm_hwm_bytes(status_text: str) -> int:
    """VmHWM (peak resident set) in bytes from the text of /proc/PID/status (0 if absent)."""
    for line in status_text.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


class PeakSampler(threading.Thread):
    """Every ``every`` seconds, the VmHWM of every process below ``root``; ``peak(after)`` is the largest of
    those first seen after a time (the job's child, forked when a worker claims it)."""

    def __init__(self, root: int, every: float = 0.5) -> None:
        super().__init__(daemon=True)
        self.root, self.every, self.stopped = root, every, threading.Event()
        self.seen: dict[int, tuple[float, int]] = {}  # pid -> (first seen, largest VmHWM)

    def run(self) -> None:
        while not self.stopped.wait(self.every):
            for pid in descendants(self.root):
                try:
                    hwm = vm_hwm_bytes(Path(f"/proc/{pid}/status").read_text())
                except OSError:
                    continue
                first, old = self.seen.get(pid, (time.time(), 0))
                self.seen[pid] = (first, max(old, hwm))

    def peak(self, after: float) -> int:
        """The largest VmHWM of the processes first seen after ``after`` (epoch seconds)."""
        return max((hwm for first, hwm in self.seen.values() if first >= after), default=0)


def _error(r: httpx.Response) -> str:
    try:
        return f"HTTP {r.status_code}: {r.json()['error']['message']}"
    except (ValueError, KeyError, TypeError):
        return f"HTTP {r.status_code}: {r.text[:300]}"


def _ok(r: httpx.Response) -> dict:
    if r.status_code >= 400:
        raise RuntimeError(_error(r))
    return r.json()


def upload(api: httpx.Client, poses: Path) -> tuple[dict, dict | None, str | None]:
    """Upload the mesh and the poses; (mesh, poses or None, refusal or None)."""
    mesh = _ok(api.post("/v1/meshes", files={"file": ("rest.obj", rest_obj(poses))}))
    try:
        with open(poses, "rb") as fh:
            r = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": (poses.name, fh)})
    except httpx.HTTPError as exc:
        return mesh, None, f"upload failed: {exc!r}"
    return (mesh, r.json(), None) if r.status_code < 400 else (mesh, None, _error(r))


def start(data_dir: Path, env: dict[str, str], workers: int) -> tuple[Launcher, str]:
    """``pdeanim serve --with-workers N`` on ``data_dir``; (launcher, API key)."""
    from pdeanim_service.settings import Settings
    from pdeanim_service.store.tenants import issue_key

    key = issue_key(Settings(data_dir=data_dir), "bench")
    launcher = Launcher(data_dir / "logs", {**os.environ, "PDEANIM_DATA_DIR": str(data_dir), **env})
    # one HTTP process: the job does not use more, and on a loaded host the supervisor of several restarted
    # them while they started (the first request after /healthz was then cut off)
    launcher.start_server("--with-workers", str(workers), "--workers", "1", "--log-level", "warning")
    return launcher, key


def probe(poses: Path, target: float, env: dict[str, str]) -> str:
    """Upload and submit with the settings ``env`` (no job worker runs it); what the service answered."""
    with tempfile.TemporaryDirectory(prefix="fit-scale-svc-") as tmp:
        launcher, key = start(Path(tmp), env, 0)
        try:
            with httpx.Client(base_url=launcher.url, headers={"Authorization": f"Bearer {key}"},
                              timeout=600) as api:
                _, got, refused = upload(api, poses)
                if refused:
                    return f"poses upload refused: {refused}"
                r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": got["id"],
                                               "params": {"target_rel_rms": target}})
                job = f"refused: {_error(r)}" if r.status_code >= 400 else "accepted"
                return f"upload accepted; fit job {job}"
        finally:
            launcher.stop()


def wait_job(api: httpx.Client, job_id: str, timeout: float) -> dict:
    """Long-poll the job until it ends or ``timeout`` passes (then it is cancelled); its last record."""
    deadline = time.monotonic() + timeout
    while True:
        job = _ok(api.get(f"/v1/jobs/{job_id}", params={"wait": 10}))
        if job["state"] in ("succeeded", "failed", "cancelled"):
            return job
        if time.monotonic() > deadline:
            api.post(f"/v1/jobs/{job_id}/cancel")
            return {**job, "state": "timed out"}


def one_run(poses: Path, name: str, target: float, workers: int, env: dict[str, str], timeout: float) -> dict:
    """Upload, submit, wait: the row of one service run with ``workers`` job workers."""
    frames, vertices = input_shape(poses)
    row: dict = {"input": name, "workers": workers, "frames": frames, "vertices": vertices,
                 "load": os.getloadavg()[0], "peak_mib": None, "met": None}
    with tempfile.TemporaryDirectory(prefix="fit-scale-svc-") as tmp:
        launcher, key = start(Path(tmp), env, workers)
        sampler = PeakSampler(launcher.server.pid)
        sampler.start()
        try:
            with httpx.Client(base_url=launcher.url, headers={"Authorization": f"Bearer {key}"},
                              timeout=600) as api:
                t0 = time.perf_counter()
                _, got, refused = upload(api, poses)
                row["upload_s"] = time.perf_counter() - t0
                if refused:
                    return {**row, "state": refused}
                submitted, t0 = time.time(), time.perf_counter()
                job = _ok(api.post("/v1/jobs", json={"kind": "fit", "poses_id": got["id"],
                                                     "params": {"target_rel_rms": target}}))
                job = wait_job(api, job["id"], timeout)
                row.update(job_wall_s=time.perf_counter() - t0, state=job["state"],
                           error=(job.get("error") or {}).get("message"))
                if job.get("started_at") and job.get("finished_at"):
                    row["job_run_s"] = job["finished_at"] - job["started_at"]
                    row["queued_s"] = job["started_at"] - job["created_at"]
                row["peak_mib"] = sampler.peak(submitted) / 2**20 or None
                if job["state"] == "succeeded":
                    clip = _ok(api.get(f"/v1/clips/{job['result']['clip_id']}"))
                    row.update(clip_summary(clip, target), fv_per_s=frames * vertices / row["job_wall_s"])
        finally:
            sampler.stopped.set()
            launcher.stop()
    row["load_after"] = os.getloadavg()[0]
    return row


def clip_summary(clip: dict, target: float) -> dict:
    """Errors, bytes and whether the rel-RMS target was met, from a clip's metadata."""
    errors, sizes = clip.get("errors", {}), clip.get("sizes", {})
    met = errors.get("target_met")
    if met is None and errors.get("rel_rms") is not None:
        met = errors["rel_rms"] <= target
    return {"met": met, "rel_rms": errors.get("rel_rms"), "rel_max": errors.get("rel_max"),
            "bytes": (sizes.get("topology_bytes") or 0) + (sizes.get("coefficients_bytes") or 0),
            "windowed": clip.get("info", {}).get("windowed")}


def service_runs(poses: Path, name: str, target: float, worker_counts: list[int], extra: dict[str, str],
                 timeout: float) -> dict:
    """Part (c): the defaults probe, then one run per worker count with the raised settings; printed as it
    goes."""
    frames, vertices = input_shape(poses)
    print(f"   input {name}: {frames} x {vertices:,}, {poses.stat().st_size / 2**20:.0f} MiB", flush=True)
    raised = raised_settings(poses, frames, vertices)
    said = [f"with the default settings: {probe(poses, target, {})}"]
    sizes = {k: v for k, v in raised.items() if k != "PDEANIM_JOB_MEMORY_BYTES"}
    if sizes and "PDEANIM_JOB_MEMORY_BYTES" in raised:
        said.append(f"with only {', '.join(sizes)} raised: {probe(poses, target, sizes)}")
    for line in said:
        print(f"   {line}", flush=True)
    env = {**raised, **PRIORITY, **extra}
    print(f"   settings raised for this input (documented in docs/operations.md): "
          f"{', '.join(f'{k}={v}' for k, v in env.items())}", flush=True)
    rows = []
    for n in worker_counts:
        row = one_run(poses, name, target, n, env, timeout)
        shown = {k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}
        print(f"   {n} job worker(s): {shown}", flush=True)
        rows.append(row)
    return {"defaults": said, "settings": env, "rows": rows}
