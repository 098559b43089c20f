"""Curve extraction benchmark (prints two tables).

1. Spatial floor (relative RMS / relative max, per motion variant) of the extracted curves against greedy
   edge paths with about the same mean points per curve, with median / 90th percentile turning angles.
2. Error-bounded curves + fit (``pdeanim.fit.fit_poses``) for target relative RMS 1e-2, 3e-3, 1e-3:
   curves, mean points per curve, segments, achieved RMS and max error, total bytes (topology + coefficients)
   against raw float32 and against a PCA baseline (mean + k bases + per-frame weights, float32, plus the same
   int32 faces; k is the smallest reaching the clip's achieved RMS), and the fit's own automatic curves.

Data: tests/data/AnimatedMorphSphere.npz (216 frames); spot/bob with a synthetic bend + twist + travelling
wave (``pdeanim.curves.deform.bend_twist``, 60 frames); spot/bob simulated with ``pdeanim.sim`` (XPBD, 48
frames, bottom pinned, top twisted 35 degrees and back; meshes as ``pdeanim.mesh.io.load_mesh`` reads them).
Run: .venv/bin/python benchmarks/curves_table.py [--quick]
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

from pdeanim.curves import extract_curves
from pdeanim.curves.bounded import bounded_curves
from pdeanim.curves.deform import bend_twist
from pdeanim.curves.floor import spatial_floor
from pdeanim.curves.naive import greedy_edge_curves
from pdeanim.curves.quality import quality_summary
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.poses import Poses, make_poses

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
TARGETS = (1e-2, 3e-3, 1e-3)
MOTIONS = ("absolute", "displacement", "rigid")


def datasets(n_frames: int) -> dict[str, Poses]:
    """Poses of the benchmark sequences."""
    d = np.load(DATA / "AnimatedMorphSphere.npz")
    out = {"morph-sphere": make_poses(d["vertices"], d["faces"], d["times"].astype(np.float64))}
    for name in ("spot", "bob"):
        m = trimesh.load(DATA / f"{name}.obj", process=False)
        out[f"{name}-bend"] = make_poses(bend_twist(np.asarray(m.vertices), n_frames), np.asarray(m.faces))
    for name in ("spot", "bob"):
        out[f"{name}-sim"] = simulated(name, n_frames * 4 // 5)
    return out


def simulated(name: str, n_frames: int) -> Poses:
    """XPBD poses of a test mesh: bottom quarter pinned, top quarter twisted 35 degrees about y and back."""
    from pdeanim.mesh.io import load_mesh
    from pdeanim.sim.scene import SceneParams
    from pdeanim.sim.simulate import simulate_mesh

    top = {"box": [0, 0.75, 0, 1, 1, 1], "relative": True}
    keys = [{"t": 0, "rotate": [0, 1, 0, 0]}, {"t": 0.5, "rotate": [0, 1, 0, 35], "translate": [0.05, 0, 0]},
            {"t": 1, "rotate": [0, 1, 0, 0]}]
    scene = SceneParams(frames=n_frames, young=3e4, target_tets=3000,
                        pins=[{"box": [0, 0, 0, 1, 0.25, 1], "relative": True}],
                        drivers=[{"region": top, "keyframes": keys}])
    return simulate_mesh(load_mesh(DATA / f"{name}.obj"), scene)


def matched_naive(rest: np.ndarray, faces: np.ndarray, mean_points: float):
    """Greedy edge paths whose mean points per curve is closest to mean_points."""
    best = None
    for tp in range(8, 19, 2):
        cs = greedy_edge_curves(rest, faces, target_points=tp)
        q = quality_summary(rest, faces, cs)
        if best is None or abs(q["mean_points"] - mean_points) < abs(best[1]["mean_points"] - mean_points):
            best = (cs, q)
    return best


def floor_table(data: dict[str, Poses]) -> None:
    """Print the floor of smooth curves against greedy edge paths."""
    print("\n## Spatial floor (rel RMS / rel max), 10-point target; turning angle median/p90 in degrees")
    print(f"{'data':14s} {'curves':22s} {'C':>5s} {'pts':>5s} {'turn':>8s} {'s':>5s} "
          + " ".join(f"{m:>19s}" for m in MOTIONS))
    for name, p in data.items():
        rest = p.vertices[0].astype(np.float64)
        t0 = time.perf_counter()
        smooth = extract_curves(rest, p.faces)
        dt = time.perf_counter() - t0
        qs = quality_summary(rest, p.faces, smooth)
        rows = [("meridians (default)", smooth, qs, dt)]
        t0 = time.perf_counter()
        rings = extract_curves(rest, p.faces, method="rings")
        rows.append(("rings", rings, quality_summary(rest, p.faces, rings), time.perf_counter() - t0))
        naive, qn = matched_naive(rest, p.faces, qs["mean_points"])
        rows.append(("greedy edge paths", naive, qn, float("nan")))
        for label, cs, q, t in rows:
            fl = [spatial_floor(p.vertices, cs, m) for m in MOTIONS]
            print(f"{name:14s} {label:22s} {cs.n_curves:5d} {q['mean_points']:5.1f} "
                  f"{q['turn_median_deg']:3.0f}/{q['turn_p90_deg']:3.0f} {t:5.2f} "
                  + " ".join(f"{r.rel_rms:9.2e}/{r.rel_max:9.2e}" for r in fl))


def pca_bytes(x: np.ndarray, rms: float, n_faces: int) -> tuple[int, int]:
    """(k, bytes) of the smallest PCA (mean + k bases + weights) whose RMS per vertex is <= rms."""
    f, v, _ = x.shape
    a = x.reshape(f, -1).astype(np.float64)
    a = a - a.mean(axis=0)
    s = np.linalg.svd(a, compute_uv=False)
    tail = np.r_[np.cumsum((s**2)[::-1])[::-1], 0.0]  # tail[k] = squared error with k bases
    err = np.sqrt(tail / (f * v))
    k = int(np.argmax(err <= rms))
    return k, 4 * (3 * v + k * 3 * v + f * k) + 4 * 3 * n_faces


def fit_row(name: str, p: Poses, target: float, label: str, curves) -> None:
    """Fit one target with bounded curves ("bounded") or the fit's own curves (None) and print a row."""
    t0 = time.perf_counter()
    if curves == "bounded":
        curves, _ = bounded_curves(p.vertices, p.faces, target, motion="displacement")
    t1 = time.perf_counter()
    parts = fit_poses(p, FitOptions(target_rel_rms=target), curves=curves)
    t2 = time.perf_counter()
    r = parts.report
    total = len(parts.topology) + len(parts.coefficients)
    raw = p.n_frames * p.n_vertices * 12
    k, pb = pca_bytes(p.vertices, r["rms"], len(p.faces))
    n_pts = p.n_vertices / max(1, r["curves"])
    print(f"{name:14s} {target:7.0e} {label:8s} {r['curves']:5d} {n_pts:5.1f} {r['segments']:4d} "
          f"{r['rel_rms']:9.2e} {r['rel_max']:9.2e} {str(r['target_met']):>5s} {total:9d} {total / raw:7.4f} "
          f"{k:4d} {pb:9d} {total / pb:6.2f} {t1 - t0:6.2f} {t2 - t1:6.2f}", flush=True)


def fit_table(data: dict[str, Poses]) -> None:
    """Print the error-bounded curves + fit table."""
    print("\n## Error-bounded curves + fit (motion displacement); bytes = topology + coefficients")
    print(f"{'data':14s} {'target':>7s} {'curves':8s} {'C':>5s} {'V/C':>5s} {'seg':>4s} {'rel_rms':>9s} "
          f"{'rel_max':>9s} {'met':>5s} {'bytes':>9s} {'/raw':>7s} {'pcaK':>4s} {'pca_B':>9s} {'/pca':>6s} "
          f"{'t_cur':>6s} {'t_fit':>6s}")
    for name, p in data.items():
        for target in TARGETS:
            fit_row(name, p, target, "bounded", "bounded")
            fit_row(name, p, target, "fit-auto", None)


def speed_row() -> None:
    """Print the extraction time on bob subdivided once (about 22k vertices)."""
    m = trimesh.load(DATA / "bob.obj", process=False)
    v, f = trimesh.remesh.subdivide(np.asarray(m.vertices), np.asarray(m.faces))
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        cs = extract_curves(v, f)
        runs.append(time.perf_counter() - t0)
    print(f"\n## Speed: extract_curves on {len(v)} vertices: median {np.median(runs):.2f} s of {len(runs)} "
          f"runs (min {min(runs):.2f}, max {max(runs):.2f}), {cs.n_curves} curves; "
          f"load average {os.getloadavg()[0]:.1f}")


def main() -> None:
    """Print both tables (--quick: 20 synthetic frames instead of 60)."""
    quick = "--quick" in sys.argv
    data = datasets(20 if quick else 60)
    print("CPU-only; timings in seconds, measured on a shared machine (contended).")
    speed_row()
    floor_table(data)
    fit_table(data)


if __name__ == "__main__":
    main()
