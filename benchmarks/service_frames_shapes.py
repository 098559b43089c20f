"""The clip shapes of ``service_frames.py``: poses as users make them (a captured noisy sequence, a simulated
one, a long one, a smooth generated one), uploaded and fitted through the API at rel. RMS 3e-3."""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

SHAPES = ("captured", "simulated", "long", "generated")
DESCRIPTIONS = {
    "captured": "samba (captured, noisy), first 60 frames, two copies side by side",
    "simulated": "spot simulated by the service (XPBD), 120 frames",
    "long": "pdance, 201 frames",
    "generated": "spot subdivided to 20k vertices, generated smooth sway, 61 frames",
}


def npz_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """POSES.npz of (F, V, 3) ``vertices`` and (T, 3) ``faces``."""
    buf = io.BytesIO()
    np.savez(buf, vertices=np.asarray(vertices, np.float32), faces=np.asarray(faces, np.int32))
    return buf.getvalue()


def captured(sequences: Path) -> tuple[np.ndarray, np.ndarray]:
    """Samba's first 60 frames, two copies side by side (19,942 vertices): (F, V, 3) and faces."""
    d = np.load(sequences / "samba.npz")
    v, f = d["vertices"][:60].astype(np.float32), d["faces"].astype(np.int64)
    shift = np.array([1.2 * float(np.ptp(v[0][:, 0])), 0.0, 0.0], np.float32)
    return np.concatenate([v, v + shift], axis=1), np.concatenate([f, f + v.shape[1]])


def long(sequences: Path) -> tuple[np.ndarray, np.ndarray]:
    """Pdance, all 201 frames (7,061 vertices)."""
    d = np.load(sequences / "pdance.npz")
    return d["vertices"].astype(np.float32), d["faces"].astype(np.int64)


def fit_uploaded(api: httpx.Client, name: str, vertices: np.ndarray, faces: np.ndarray, target: float,
                 obj_bytes: Callable, check: Callable, wait_job: Callable) -> dict:
    """Upload the first frame as the mesh and the frames as its poses, fit them at ``target``; the clip."""
    mesh = check(api.post("/v1/meshes", files={"file": (f"{name}.obj", obj_bytes(vertices[0], faces))}))
    poses = check(api.post(f"/v1/meshes/{mesh['id']}/poses",
                           files={"file": ("poses.npz", npz_bytes(vertices, faces))}))
    job = check(api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses["id"],
                                           "params": {"target_rel_rms": target}}))
    job = wait_job(api, job["id"], 1800)
    return check(api.get(f"/v1/clips/{job['result']['clip_id']}"))


def simulated(api: httpx.Client, spot: Path, target: float, check: Callable, wait_job: Callable) -> dict:
    """``simulate`` spot for 120 frames (seed 0) and fit the poses at ``target`` in the same job; the clip."""
    mesh = check(api.post("/v1/meshes", files={"file": ("spot.obj", spot.read_bytes())}))
    job = check(api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"], "then_fit": True,
                                           "params": {"frames": 120, "seed": 0},
                                           "fit": {"target_rel_rms": target}}))
    job = wait_job(api, job["id"], 1800)
    return check(api.get(f"/v1/clips/{job['result']['clip_id']}"))
