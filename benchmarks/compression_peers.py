"""Peer benchmark of the clip's size against what game developers ship, all scored by the same metric code.

For each pose sequence (``.npz`` with ``vertices`` (F, V, 3) and ``faces``; read in place from the shared data
folder, never copied into the repository):

* ``pde``: this project, ``pdeanim fit`` at rel-RMS targets 1e-2, 3e-3, 1e-3 and a rel-max target, each in its
  own process (fit time, peak memory by resource.getrusage, exit code); bytes = topology + coefficients parts
  as the HTTP API serves them (no fit report);
* ``pca``: mean + k bases + per-frame weights, float32, and 16-bit-quantised + zstd;
* ``gltfpack``: morph-target GLB of the frames (our glTF writer), ``gltfpack -cc -vp N`` (N = 8..16), decoded
  with meshoptimizer's decoder (node) and matched back to the source vertices by nearest trajectory;
* ``dembones`` (only with ``--dembones``; slow, cached on disk): 8/16/32 bones, <= 4 influences;
* ``keyframes``: linear interpolation of evenly spaced keyframes (float32 frames);
* ``heldout``: fit from every 4th frame, error on the frames left out, against linear and Catmull-Rom
  interpolation of the kept frames.

Every method is scored with :func:`pdeanim.model.metrics.error_summary` (rel-RMS, rel-max to the first frame's
bounding-box diagonal, Karni-Gotsman). "zstd" = every file/array zstd -19 (PyPI ``zstandard``), faces
included.
Writes ``results.json``, ``table.md`` and one Pareto plot per sequence (zstd bytes vs rel-RMS, log-log) into
``--out``. Run ``python benchmarks/compression_peers.py --help``; see the README section "Compression
benchmark".
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pdeanim.model.metrics import bbox_diagonal, error_summary  # noqa: E402

PEERS_DIR = ROOT / "benchmarks" / "peers"
ALL_METHODS = ("pde", "pca", "gltfpack", "dembones", "keyframes", "heldout", "scaling")
PDE_TARGETS = (("rel_rms", 1e-2), ("rel_rms", 3e-3), ("rel_rms", 1e-3), ("rel_max", 1e-2))
SUMMARY_TARGETS = (1e-2, 3e-3, 1e-3)
PCA_K = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64)
VP_BITS = tuple(range(8, 17))
BONES = (8, 16, 32)
DEMBONES_ITERS = 30
KEYFRAME_COUNTS = (3, 5, 9, 13, 17, 25, 33, 49, 65, 101)
FPS = 30.0


# ----------------------------------------------------------------------------------------------- helpers

def log(msg: str) -> None:
    """Progress line on stderr with the load average."""
    print(f"[{time.strftime('%H:%M:%S')} load {os.getloadavg()[0]:.1f}] {msg}", file=sys.stderr, flush=True)


def zstd_len(*blobs: bytes | np.ndarray) -> int:
    """Sum of the zstd -19 sizes of each blob (arrays by their raw bytes)."""
    import zstandard

    c = zstandard.ZstdCompressor(level=19)
    return sum(len(c.compress(b.tobytes() if isinstance(b, np.ndarray) else bytes(b))) for b in blobs)


def quantise(
    a: np.ndarray, axis: tuple[int, ...] | int | None, bits: int = 16
) -> tuple[np.ndarray, np.ndarray]:
    """Uniform quantisation to unsigned ``bits`` with a [min, max] range over ``axis`` (kept dims):
    (codes uint16, dequantised float64). The ranges cost 2 float32 per kept element (counted by callers)."""
    a = np.asarray(a, np.float64)
    lo, hi = a.min(axis=axis, keepdims=True), a.max(axis=axis, keepdims=True)
    scale = np.where(hi > lo, (hi - lo) / (2**bits - 1), 1.0)
    q = np.rint((a - lo) / scale).astype(np.uint16 if bits <= 16 else np.uint32)
    return q, lo + q * scale


def faces_bytes(faces: np.ndarray) -> int:
    """zstd of int32 faces (what the PCA, keyframe and skinning payloads ship)."""
    return zstd_len(np.asarray(faces, np.int32))


def row(method: str, setting: str, served: int, zstd: int, err: dict, **extra) -> dict:
    """One result row."""
    return {"method": method, "setting": setting, "bytes": int(served), "zstd_bytes": int(zstd),
            "rel_rms": err["rel_rms"], "rel_max": err["rel_max"], "kg": err["kg"], **extra}


def find_sequences(data: Path | None) -> Path:
    """The sequence folder: --data, $PDEANIM_SEQUENCES, or ../shared/data/sequences next to the repository."""
    candidates = [data] if data else []
    if os.environ.get("PDEANIM_SEQUENCES"):
        candidates.append(Path(os.environ["PDEANIM_SEQUENCES"]))
    candidates += [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
    for c in candidates:
        if c and c.is_dir():
            return c
    raise SystemExit("no sequence folder: give --data DIR or set PDEANIM_SEQUENCES")


# ----------------------------------------------------------------------------------------------- pde

CHILD = ("import re, resource, sys, time; from service.cli import main; t = time.perf_counter(); "
         "rc = main(sys.argv[1:]); s = time.perf_counter() - t; "
         "m = re.search(r'VmHWM:\\s*(\\d+)', open('/proc/self/status').read()); "
         "kb = int(m.group(1)) if m else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; "
         "print('BENCH', s, kb, file=sys.stderr); sys.exit(rc)")
"""Runs ``pdeanim fit`` and prints its seconds and peak RSS. The peak is the process's own VmHWM: on Linux
``getrusage(RUSAGE_SELF).ru_maxrss`` of a forked + exec'd child also counts the parent's RSS at the fork (it
survives exec), which made every fit of a small sequence look as large as this benchmark process."""


def run_fit(seq: Path, out: Path, flag: str, value: float, timeout: float, extra: list[str]) -> dict:
    """``pdeanim fit`` in a child process: exit code, seconds, peak RSS (MB), stderr tail."""
    cmd = [
        sys.executable,
        "-c",
        CHILD,
        "fit",
        str(seq),
        "--out",
        str(out),
        f"--target-{flag.replace('_', '-')}",
        str(value),
        *extra,
    ]
    try:
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"rc": None, "timeout": True}
    seconds = peak = None
    for line in p.stderr.splitlines():
        if line.startswith("BENCH "):
            _, s, kb = line.split()
            seconds, peak = float(s), int(kb) / 1024.0
    tail = [ln for ln in p.stderr.splitlines() if ln.startswith("pdeanim fit:") or "Error" in ln]
    return {"rc": p.returncode, "seconds": seconds, "peak_mb": peak, "message": " ".join(tail)[-400:]}


def clip_errors(parts, X: np.ndarray) -> tuple[dict, object]:  # noqa: ANN001
    """Errors of a clip evaluated at every source frame."""
    from pdeanim.clip import load_clip

    clip = load_clip(parts.topology, parts.coefficients)
    return error_summary(X, clip.evaluate(clip.frame_t())), clip


def method_pde(name: str, seq: Path, X: np.ndarray, faces: np.ndarray, work: Path, args) -> list[dict]:  # noqa: ANN001
    """This project at each target (the clip format the CLI writes by default)."""
    from pdeanim.clip import read_clip_file

    rows = []
    for flag, value in PDE_TARGETS:
        out = work / f"{name}-{flag}-{value:g}.clip"
        log(f"{name}: pde fit --target-{flag} {value:g}")
        res = run_fit(seq, out, flag, value, args.fit_timeout, ["--max-segments", str(args.max_segments)])
        if res.get("timeout") or not out.exists():
            log(f"{name}: pde {flag} {value:g}: no clip ({res})")
            rows.append({"method": "pde", "setting": f"{flag} {value:g}", "failed": str(res)})
            continue
        parts = read_clip_file(out)
        err, _clip = clip_errors(parts, X)
        served = len(parts.topology) + len(parts.coefficients)
        r = row("pde", f"{flag} {value:g}", served, zstd_len(parts.topology, parts.coefficients), err,
                fit_s=res["seconds"], peak_mb=res["peak_mb"], exit_code=res["rc"],
                target_met=res["rc"] == 0, segments=parts.report.get("segments"),
                curves=parts.report.get("curves"), message=res.get("message", ""))
        rows.append(r)
        log(f"{name}: pde {flag} {value:g}: {served} B, rel-rms {err['rel_rms']:.3g}, exit {res['rc']}, "
            f"{res['seconds']:.1f} s, {res['peak_mb']:.0f} MB")
    return rows


# ----------------------------------------------------------------------------------------------- pca

def method_pca(X: np.ndarray, faces: np.ndarray) -> list[dict]:
    """Mean + k bases + weights, float32 and 16-bit bases (one range per basis) + zstd."""
    F, V = X.shape[:2]
    A = X.reshape(F, -1).astype(np.float64)
    mean = A.mean(0)
    U, s, Vt = np.linalg.svd(A - mean, full_matrices=False)
    fb = faces_bytes(faces)
    rows = []
    for k in pca_ks(s, F, V, bbox_diagonal(X[0])):
        W, B = U[:, :k] * s[:k], Vt[:k]
        approx = (mean + W @ B).reshape(X.shape)
        f32 = [mean.astype(np.float32), B.astype(np.float32), W.astype(np.float32)]
        served = sum(a.nbytes for a in f32) + faces.size * 4
        rows.append(row("pca f32", f"k={k}", served, zstd_len(*f32) + fb, error_summary(X, approx)))
        qm, mean_dq = quantise(mean.reshape(V, 3), axis=0)
        qb, B_dq = quantise(B, axis=1)
        approx_q = (mean_dq.reshape(-1) + W.astype(np.float32) @ B_dq).reshape(X.shape)
        served_q = qm.nbytes + qb.nbytes + W.size * 4 + (3 + k) * 8 + faces.size * 4
        zq = zstd_len(qm, qb, W.astype(np.float32)) + (3 + k) * 8 + fb
        rows.append(row("pca q16+zstd", f"k={k}", served_q, zq, error_summary(X, approx_q)))
    return rows


def pca_ks(s: np.ndarray, F: int, V: int, diag: float, lo: float = 3e-4, hi: float = 3e-2) -> list[int]:
    """The k of PCA_K whose float64 rel-RMS (from the tail singular values) lies in [lo, hi], plus one on
    each side: the others are far from every target and only cost zstd time on large sequences."""
    tail = np.concatenate([np.cumsum((s * s)[::-1])[::-1], [0.0]])
    ks = [k for k in PCA_K if k < F]
    rel = np.array([np.sqrt(tail[k] / (F * V)) / diag for k in ks])
    inside = np.flatnonzero((rel >= lo) & (rel <= hi))
    if not len(inside):
        inside = np.array([int(np.argmin(np.abs(np.log(np.maximum(rel, 1e-30) / np.sqrt(lo * hi)))))])
    return ks[max(inside[0] - 1, 0): inside[-1] + 2]


# ----------------------------------------------------------------------------------------------- gltfpack

def match_vertices(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Index into Y's vertices of the nearest trajectory of every source vertex (gltfpack welds and
    reorders)."""
    from scipy.spatial import cKDTree

    pick = np.unique(np.linspace(0, len(X) - 1, min(len(X), 8)).astype(int))
    feat = lambda P: np.ascontiguousarray(np.moveaxis(P[pick], 0, 1).reshape(P.shape[1], -1))  # noqa: E731
    return cKDTree(feat(Y)).query(feat(X), workers=1)[1]


GLTFPACK_CLI = PEERS_DIR / "node_modules" / "gltfpack" / "cli.js"


def method_gltfpack(X: np.ndarray, faces: np.ndarray, work: Path, timeout: float) -> list[dict]:
    """Morph-target GLB -> gltfpack -cc -vp N -> meshopt decode -> our reader -> score."""
    from pdeanim.gltf.read import read_animated_poses
    from pdeanim.gltf.write import animation_glb

    cli = GLTFPACK_CLI
    src = work / "frames.glb"
    src.write_bytes(animation_glb(X, np.arange(len(X)) / FPS, faces, normals=False))
    rows = []
    for n in VP_BITS:
        packed, plain = work / f"vp{n}.glb", work / f"vp{n}-plain.glb"
        t = time.perf_counter()
        p = subprocess.run(["node", str(cli), "-i", str(src), "-o", str(packed), "-cc", "-vp", str(n)],
                           capture_output=True, text=True, timeout=timeout)
        secs = time.perf_counter() - t
        if p.returncode != 0:
            log(f"gltfpack -vp {n} failed: {p.stderr[-300:]}")
            continue
        d = subprocess.run(["node", str(PEERS_DIR / "decode_meshopt.mjs"), str(packed), str(plain)],
                           capture_output=True, text=True, timeout=timeout)
        if d.returncode != 0:
            log(f"meshopt decode of -vp {n} failed: {d.stderr[-300:]}")
            continue
        Y = read_animated_poses(plain, fps=FPS).vertices.astype(np.float64)
        if len(Y) != len(X):
            log(f"gltfpack -vp {n}: {len(Y)} frames decoded for {len(X)}; compared on the common prefix")
        m = min(len(Y), len(X))
        approx = Y[:m][:, match_vertices(X[:m], Y[:m])]
        blob = packed.read_bytes()
        rows.append(row("gltfpack", f"-cc -vp {n}", len(blob), zstd_len(blob), error_summary(X[:m], approx),
                        pack_s=secs, decoded_vertices=int(Y.shape[1])))
    return rows


# ----------------------------------------------------------------------------------------------- dem bones

def dembones_solve(name: str, X: np.ndarray, faces: np.ndarray, bones: int, cache: Path) -> dict:
    """Weights (B, V) and transforms (F, B, 4, 4) of Dem Bones, cached on disk (outside the repository)."""
    path = cache / f"dembones-{name}-{X.shape[0]}x{X.shape[1]}-b{bones}-i{DEMBONES_ITERS}.npz"
    if path.exists():
        with np.load(path) as d:
            return {"weights": d["weights"], "transforms": d["transforms"], "seconds": float(d["seconds"])}
    from py_dem_bones import solve_skinning

    t = time.perf_counter()
    res = solve_skinning(X[0].astype(np.float64), X.astype(np.float64), bones, faces=faces, max_influences=4,
                         iterations=DEMBONES_ITERS)
    secs = time.perf_counter() - t
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, weights=res.weights, transforms=res.transforms, seconds=secs)
    return {"weights": res.weights, "transforms": res.transforms, "seconds": secs}


def skin(rest: np.ndarray, W: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Linear blend skinning: rest (V, 3), weights (V, B), rotations (F, B, 3, 3), translations (F, B, 3)."""
    out = np.empty((len(R), len(rest), 3))
    for f in range(len(R)):
        P = np.einsum("bij,vj->bvi", R[f], rest) + T[f][:, None, :]
        out[f] = np.einsum("vb,bvi->vi", W, P)
    return out


def method_dembones(name: str, X: np.ndarray, faces: np.ndarray, cache: Path) -> list[dict]:
    """Dem Bones at 8/16/32 bones: float32 and quantised payloads (rest 16-bit, top-4 weights and bone indices
    uint8, quaternion + translation per bone and frame 16-bit), each + zstd, faces included."""
    from scipy.spatial.transform import Rotation

    rows = []
    fb = faces_bytes(faces)
    for b in BONES:
        log(f"{name}: dem bones {b} bones")
        sol = dembones_solve(name, X, faces, b, cache)
        Wt, M = sol["weights"].T, sol["transforms"]  # (V, B), (F, B, 4, 4)
        B = Wt.shape[1]
        top = np.argsort(-Wt, axis=1)[:, :4]
        wv = np.take_along_axis(Wt, top, 1)
        quat = Rotation.from_matrix(M[..., :3, :3].reshape(-1, 3, 3)).as_quat().reshape(len(M), B, 4)
        trans = M[..., :3, 3]
        Wd = np.zeros_like(Wt)
        np.put_along_axis(Wd, top, wv, 1)
        err = error_summary(X, skin(X[0].astype(np.float64), Wd, M[..., :3, :3], trans))
        f32 = [X[0].astype(np.float32), wv.astype(np.float32), top.astype(np.uint8),
               np.concatenate([quat, trans], -1).astype(np.float32)]
        rows.append(row("dembones f32", f"{b} bones", sum(a.nbytes for a in f32) + faces.size * 4,
                        zstd_len(*f32) + fb, err, solve_s=sol["seconds"]))
        q_rest, rest_dq = quantise(X[0], axis=0)
        w8 = np.rint(wv / np.maximum(wv.sum(1, keepdims=True), 1e-12) * 255).astype(np.uint8)
        q_quat, quat_dq = quantise(quat, axis=(0, 2))
        q_tr, tr_dq = quantise(trans, axis=(0, 2))
        Wq = np.zeros_like(Wt)
        np.put_along_axis(Wq, top, w8 / 255.0, 1)
        Rq = Rotation.from_quat(quat_dq.reshape(-1, 4)).as_matrix().reshape(len(M), B, 3, 3)
        err_q = error_summary(X, skin(rest_dq, Wq, Rq, tr_dq))
        qs = [q_rest, w8, top.astype(np.uint8), q_quat, q_tr]
        ranges = (3 + 2 * B) * 8
        rows.append(
            row(
                "dembones q16+zstd",
                f"{b} bones",
                sum(a.nbytes for a in qs) + ranges + faces.size * 4,
                zstd_len(*qs) + ranges + fb,
                err_q,
                solve_s=sol["seconds"],
            )
        )
    return rows


# ----------------------------------------------------------------------------------------------- keyframes

def method_keyframes(X: np.ndarray, faces: np.ndarray) -> list[dict]:
    """Linear interpolation of K evenly spaced float32 keyframes."""
    from pdeanim.fit.heldout import linear_interpolation

    F = len(X)
    times = np.arange(F, dtype=np.float64)
    fb = faces_bytes(faces)
    rows = []
    for k in [k for k in KEYFRAME_COUNTS if k < F]:
        keep = np.unique(np.rint(np.linspace(0, F - 1, k)).astype(int))
        approx = linear_interpolation(times[keep], X[keep].astype(np.float64), times)
        kf = X[keep].astype(np.float32)
        rows.append(row("keyframes", f"{len(keep)} frames", kf.nbytes + faces.size * 4, zstd_len(kf) + fb,
                        error_summary(X, approx)))
    return rows


# ----------------------------------------------------------------------------------------------- held out

def method_heldout(X: np.ndarray, faces: np.ndarray, target: float) -> list[dict]:
    """Fit from every 4th frame; error on the frames left out vs linear and Catmull-Rom of the kept frames.

    The fit's target on the kept frames is the tighter of ``target`` and a quarter of the held-out error of
    the better interpolant (a fit that misses the kept frames by more than the interpolants miss the others
    cannot match them)."""
    from pdeanim.fit import FitOptions
    from pdeanim.fit.heldout import (
        catmull_rom_interpolation,
        heldout_comparison,
        kept_frames,
        linear_interpolation,
    )
    from pdeanim.poses import make_poses

    keep = kept_frames(len(X), 4)
    out_idx = np.setdiff1d(np.arange(len(X)), keep)
    times = np.arange(len(X), dtype=np.float64)
    lin = error_summary(
        X[out_idx], linear_interpolation(times[keep], X[keep], times[out_idx]), bbox_diagonal(X[0])
    )
    cr = error_summary(
        X[out_idx], catmull_rom_interpolation(times[keep], X[keep], times[out_idx]), bbox_diagonal(X[0])
    )
    fit_target = float(min(target, 0.25 * lin["rel_rms"], 0.25 * cr["rel_rms"]))
    t = time.perf_counter()
    res = heldout_comparison(make_poses(X, faces), 4, FitOptions(target_rel_rms=fit_target, best_effort=True))
    secs = time.perf_counter() - t
    rows = []
    for key, label in (("pde", f"pde (fit to rel-rms {fit_target:.2g} on kept)"), ("linear", "linear"),
                       ("catmull_rom", "catmull-rom")):
        e = res[key]
        rows.append({"method": "heldout", "setting": label, "rel_rms": e["rel_rms"], "rel_max": e["rel_max"],
                     "kg": e["kg"], "kept": res["kept_frames"], "heldout": res["heldout_frames"],
                     **({"fit_s": secs, "fit_rel_rms_on_kept": res["fit_report"]["rel_rms"],
                         "segments": res["fit_report"]["segments"]} if key == "pde" else {})})
    return rows


# ----------------------------------------------------------------------------------------------- scaling

def method_scaling(name: str, X: np.ndarray, faces: np.ndarray, work: Path, timeout: float) -> list[dict]:
    """Fit time and peak memory against frames x vertices: ``pdeanim fit --segments 8`` (a fixed amount of
    time-stage work per frame) on the first quarter, half and all frames, each in its own process."""
    rows = []
    F = len(X)
    for frames in sorted({max(9, F // 4), max(9, F // 2), F}):
        if frames > F:
            continue
        path = work / f"{name}-first{frames}.npz"
        np.savez(path, vertices=X[:frames].astype(np.float32), faces=faces)
        out = work / f"{name}-first{frames}.clip"
        cmd = [sys.executable, "-c", CHILD, "fit", str(path), "--out", str(out), "--segments", "8", "--quiet"]
        try:
            p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            rows.append({"method": "scaling", "setting": f"{frames} frames", "failed": "timeout"})
            continue
        line = next((ln for ln in p.stderr.splitlines() if ln.startswith("BENCH ")), None)
        if line is None:
            rows.append({"method": "scaling", "setting": f"{frames} frames", "failed": p.stderr[-300:]})
            continue
        _, secs, kb = line.split()
        fv = frames * X.shape[1]
        rows.append({"method": "scaling", "setting": f"{frames} frames", "frames_x_vertices": fv,
                     "fit_s": float(secs), "peak_mb": int(kb) / 1024.0,
                     "us_per_frame_vertex": 1e6 * float(secs) / fv,
                     "bytes_per_frame_vertex": int(kb) * 1024.0 / fv})
        log(f"{name}: scaling {frames} frames: {float(secs):.1f} s, {int(kb) / 1024:.0f} MB")
    return rows


# ----------------------------------------------------------------------------------------------- report

def best_under(rows: list[dict], method: str, target: float, key: str = "zstd_bytes") -> dict | None:
    """The smallest (by ``key``) row of ``method`` with rel-RMS <= target."""
    ok = [
        r
        for r in rows
        if r.get("method") == method and "rel_rms" in r and key in r and r["rel_rms"] <= target
    ]
    return min(ok, key=lambda r: r[key]) if ok else None


def fmt_bytes(n: float | None) -> str:
    return "-" if n is None else f"{n / 1000:,.0f} K" if n >= 10_000 else f"{n:,.0f}"


def summary_table(results: dict) -> str:
    """Markdown: per sequence and target, the smallest bytes (served / zstd) each method needs to reach it."""
    methods = [
        "pde",
        "gltfpack",
        "pca f32",
        "pca q16+zstd",
        "dembones q16+zstd",
        "keyframes",
    ]
    lines = [
        "| sequence | target rel-RMS | " + " | ".join(methods)
        + " | pde / min(gltfpack GLB, pca q16 zstd) |",
        "|---|---|" + "---|" * (len(methods) + 1),
    ]
    for name, rows in results.items():
        for tgt in SUMMARY_TARGETS:
            cells, ratio = [], "-"
            # what each peer ships: gltfpack's GLB as is, quantised PCA after zstd (the yardstick)
            peers = [b[key] for m, key in (("gltfpack", "bytes"), ("pca q16+zstd", "zstd_bytes"))
                     if (b := best_under(rows, m, tgt, key))]
            ours = next((r for r in rows if r.get("method") == "pde" and "rel_rms" in r
                         and r.get("setting") == f"rel_rms {tgt:g}"
                         and r["rel_rms"] <= tgt * (1 + 1e-9)), None)
            if peers and ours:
                ratio = f"{ours['bytes'] / min(peers):.2f}"
            for m in methods:
                b = best_under(rows, m, tgt)
                if m.startswith("pde"):  # the project's row is the fit *for* that target
                    b = next(
                        (
                            r
                            for r in rows
                            if r.get("method") == m
                            and r.get("setting") == f"rel_rms {tgt:g}"
                            and "rel_rms" in r
                        ),
                        None,
                    )
                    if b is not None and b["rel_rms"] > tgt * (1 + 1e-9):
                        cells.append(f"missed: {b['rel_rms']:.2g} in {fmt_bytes(b['bytes'])}")
                        continue
                cells.append("-" if b is None else f"{fmt_bytes(b['bytes'])} / {fmt_bytes(b['zstd_bytes'])} "
                             f"(max {b['rel_max']:.2g}, {b['setting']})")
            lines.append(f"| {name} | {tgt:g} | " + " | ".join(cells) + f" | {ratio} |")
    return "\n".join(lines)


def heldout_table(results: dict) -> str:
    """Markdown: held-out rel-RMS / rel-max per sequence for the clip, linear and Catmull-Rom."""
    lines = [
        "| sequence | kept / left out | pde fit (target on kept) | linear | Catmull-Rom | pde / linear |",
        "|---|---|---|---|---|---|",
    ]
    for name, rows in results.items():
        h = {r["setting"].split(" ")[0]: r for r in rows if r.get("method") == "heldout"}
        if not {"pde", "linear", "catmull-rom"} <= h.keys():
            continue
        p, lin, cr = h["pde"], h["linear"], h["catmull-rom"]
        lines.append(f"| {name} | {p['kept']} / {p['heldout']} | {p['rel_rms']:.3g} / {p['rel_max']:.3g} "
                     f"({p['setting'].split('rel-rms ')[1].rstrip(')')}) | {lin['rel_rms']:.3g} / "
                     f"{lin['rel_max']:.3g} | {cr['rel_rms']:.3g} / {cr['rel_max']:.3g} | "
                     f"{p['rel_rms'] / max(lin['rel_rms'], 1e-300):.2f} |")
    return "\n".join(lines)


def full_table(name: str, rows: list[dict]) -> str:
    """Markdown: every row of one sequence."""
    lines = [f"### {name}", "", "| method | setting | bytes | zstd | rel-RMS | rel-max | KG % | notes |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("method") == "scaling" and "fit_s" in r:
            lines.append(
                f"| scaling | {r['setting']} (--segments 8) | - | - | - | - | - | {r['fit_s']:.1f} s fit, "
                f"{r['peak_mb']:.0f} MB peak, {r['us_per_frame_vertex']:.2f} us and "
                f"{r['bytes_per_frame_vertex']:.0f} B per frame x vertex |"
            )
            continue
        if "rel_rms" not in r:
            lines.append(f"| {r['method']} | {r['setting']} | - | - | - | - | - | {r.get('failed', '')} |")
            continue
        notes = []
        for k, unit in (
            ("fit_s", "s fit"),
            ("peak_mb", "MB peak"),
            ("solve_s", "s solve"),
            ("pack_s", "s pack"),
        ):
            if r.get(k) is not None:
                notes.append(f"{r[k]:.1f} {unit}")
        if "exit_code" in r:
            notes.append(f"exit {r['exit_code']}, {r.get('segments')} segments, {r.get('curves')} curves")
        for k in ("note", "kept", "fit_rel_rms_on_kept"):
            if k in r:
                notes.append(
                    f"{k}={r[k]:.3g}" if isinstance(r[k], float) else f"{k}={r[k]}" if k != "note" else r[k]
                )
        lines.append(
            f"| {r['method']} | {r['setting']} | {fmt_bytes(r.get('bytes'))} | "
            f"{fmt_bytes(r.get('zstd_bytes'))} | {r['rel_rms']:.3g} | {r['rel_max']:.3g} | {r['kg']:.3g} | "
            f"{'; '.join(notes)} |"
        )
    return "\n".join(lines)


def pareto_plot(name: str, rows: list[dict], path: Path) -> None:
    """zstd bytes vs rel-RMS, log-log, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    methods = [m for m in dict.fromkeys(r["method"] for r in rows)
               if not m.startswith("heldout")]
    for m in methods:
        pts = sorted((r["zstd_bytes"], r["rel_rms"]) for r in rows
                     if r["method"] == m and r.get("zstd_bytes") and r["rel_rms"] > 0)
        if pts:
            ax.plot(*zip(*pts, strict=True), marker="o", ms=3, label=m)
    for tgt in SUMMARY_TARGETS:
        ax.axhline(tgt, color="grey", lw=0.5, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("bytes after zstd -19 (faces included)")
    ax.set_ylabel("rel-RMS (to frame 0 bbox diagonal)")
    ax.set_title(f"{name}: bytes vs error")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------------------------- main

def run_sequence(seq: Path, args) -> list[dict]:  # noqa: ANN001
    """Every selected method on one sequence."""
    name = seq.stem
    with np.load(seq) as d:
        X, faces = d["vertices"].astype(np.float64), d["faces"].astype(np.int32)
    if args.max_frames and len(X) > args.max_frames:
        X = X[: args.max_frames]
    log(f"{name}: {X.shape[0]} frames x {X.shape[1]} vertices, {len(faces)} faces")
    rows: list[dict] = [
        {
            "method": "raw",
            "setting": "float32 frames",
            "bytes": X.size * 4 + faces.size * 4,
            "rel_rms": 0.0,
            "rel_max": 0.0,
            "kg": 0.0,
        }
    ]  # (zstd -19 of all frames: minutes, skipped)
    work = Path(tempfile.mkdtemp(prefix=f"peers-{name}-"))
    src = seq
    if args.max_frames:
        src = work / f"{name}.npz"
        np.savez(src, vertices=X.astype(np.float32), faces=faces)
    try:
        steps = [("pca", lambda: method_pca(X, faces)), ("keyframes", lambda: method_keyframes(X, faces)),
                 ("gltfpack", lambda: method_gltfpack(X, faces, work, args.fit_timeout)),
                 ("pde", lambda: method_pde(name, src, X, faces, work, args)),
                 ("heldout", lambda: method_heldout(X, faces, args.heldout_target)),
                 ("scaling", lambda: method_scaling(name, X, faces, work, args.fit_timeout)),
                 ("dembones", lambda: method_dembones(name, X, faces, args.cache) if args.dembones else [])]
        for method, fn in steps:
            if method not in args.methods:
                continue
            t = time.perf_counter()
            log(f"{name}: {method}")
            new = fn()
            rows += new
            log(f"{name}: {method} done in {time.perf_counter() - t:.1f} s ({len(new)} rows)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder (results.json, table.md, plots)")
    ap.add_argument("--data", type=Path, help="sequence folder (default $PDEANIM_SEQUENCES or "
                                              "../shared/data/sequences)")
    ap.add_argument("--sequences", help="comma-separated sequence names (default: all .npz in the folder)")
    ap.add_argument("--methods", default=",".join(m for m in ALL_METHODS if m != "dembones"),
                    help=f"comma-separated subset of {','.join(ALL_METHODS)}")
    ap.add_argument("--dembones", action="store_true", help="also run Dem Bones (slow; results cached)")
    ap.add_argument(
        "--cache",
        type=Path,
        default=Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pdeanim-bench",
        help="cache folder for Dem Bones results (outside the repository)",
    )
    ap.add_argument(
        "--max-frames", type=int, help="use only the first N frames of each sequence (quick runs)"
    )
    ap.add_argument(
        "--fit-timeout", type=float, default=1800.0, help="seconds per pdeanim fit / gltfpack run"
    )
    ap.add_argument("--max-segments", type=int, default=256, help="segment cap passed to pdeanim fit")
    ap.add_argument("--resume", action="store_true",
                    help="keep the sequences already in OUT/results.json and run only the others")
    ap.add_argument("--heldout-target", type=float, default=1e-3, help="rel-RMS target of the held-out fit")
    args = ap.parse_args(argv)
    args.methods = set(args.methods.split(","))
    if args.dembones:
        args.methods.add("dembones")
    unknown = args.methods - set(ALL_METHODS)
    if unknown:
        ap.error(f"unknown methods: {', '.join(sorted(unknown))}")
    if "gltfpack" in args.methods and not GLTFPACK_CLI.exists():  # a peer left out would look like a win
        ap.error(f"{GLTFPACK_CLI} is missing: run (cd benchmarks/peers && npm ci), or leave gltfpack out of "
                 "--methods")
    folder = find_sequences(args.data)
    seqs = sorted(folder.glob("*.npz"))
    if args.sequences:
        want = args.sequences.split(",")
        seqs = sorted((s for s in seqs if s.stem in want), key=lambda s: want.index(s.stem))
        missing = set(want) - {s.stem for s in seqs}
        if missing:
            ap.error(f"no such sequences in {folder}: {', '.join(sorted(missing))}")
    args.out.mkdir(parents=True, exist_ok=True)
    loads = [os.getloadavg()]
    results: dict[str, list[dict]] = {}
    if args.resume and (args.out / "results.json").exists():
        results = json.loads((args.out / "results.json").read_text())
        log(f"resuming: {', '.join(results)} already measured")
    t0 = time.perf_counter()
    for seq in seqs:
        if seq.stem in results:
            continue
        results[seq.stem] = run_sequence(seq, args)
        loads.append(os.getloadavg())
        (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float))
        log(f"{seq.stem}: done; results so far in {args.out / 'results.json'}")
    for name, rows in results.items():
        pareto_plot(name, rows, args.out / f"pareto-{name}.png")
    load = np.array(loads)
    head = (
        f"Compression peers, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPUs, "
        f"1-min load average {load[:, 0].min():.1f}..{load[:, 0].max():.1f} during the run "
        f"(shared machine), {time.perf_counter() - t0:.0f} s in all, peak RSS of this process "
        f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )
    text = "\n\n".join(
        [
            head,
            "Smallest bytes (served / zstd -19) that reach each rel-RMS target:",
            summary_table(results),
            "Held-out frames (fit from every 4th frame; rel-RMS / rel-max at the frames left out):",
            heldout_table(results),
            *[full_table(n, r) for n, r in results.items()],
        ]
    )
    (args.out / "table.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
