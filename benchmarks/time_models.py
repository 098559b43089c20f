"""How the clip's time models compare on the benchmark sequences: each sequence fitted with `--time-model
auto` (the default: per curve coordinate, the natural spline where it fits as well, else the paper's time
pairs), `pde` (the paper's dynamic-PDE time solution alone) and `spline`, at rel-RMS 3e-3 and 1e-3.

Prints per fit: bytes of both parts, achieved rel-RMS and rel-max over the target, segments, how many curve
coordinates took the spline, the paper's pairs with a constant, or the paper's linear pair; and the held-out
error (every 4th frame kept, fitted at the same target, measured at the frames left out) against linear and
Catmull-Rom interpolation of the kept frames. Sequences are read from ../shared/data/sequences (benchmarks
only).

    .venv/bin/python benchmarks/time_models.py [--targets 3e-3,1e-3] [--sequences a,b] [--quick]
"""

from __future__ import annotations

import argparse
import datetime
import os
import time
from pathlib import Path

import numpy as np

from pdeanim.fit import FitOptions, fit_poses
from pdeanim.fit.encode import decode
from pdeanim.fit.heldout import catmull_rom_interpolation, linear_interpolation
from pdeanim.model.metrics import bbox_diagonal
from pdeanim.poses import Poses, make_poses

ROOT = Path(__file__).resolve().parents[1]
SEQUENCES = next((p for p in (ROOT.parent / "shared" / "data" / "sequences",
                              ROOT.parent.parent / "shared" / "data" / "sequences") if p.is_dir()),
                 ROOT.parent / "shared" / "data" / "sequences")
NAMES = ["AnimatedMorphSphere", "horse-collapse", "elephant-gallop", "pcow", "pdance", "samba"]
MODELS = ("auto", "pde", "spline")
KEEP_EVERY = 4


def load(name: str) -> Poses:
    """A benchmark sequence (30 fps where it has no times)."""
    d = np.load(SEQUENCES / f"{name}.npz")
    v = d["vertices"]
    times = d["times"] if "times" in d else np.arange(len(v)) / 30.0
    return make_poses(v, d["faces"], times)


def rel_rms(a: np.ndarray, b: np.ndarray, diag: float) -> float:
    d = np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1)
    return float(np.sqrt(np.mean(d * d))) / diag


def heldout(poses: Poses, model: str, target: float) -> dict[str, float]:
    """The stated protocol: frames 0, 4, 8, ... kept, fitted at the same target, errors at the others."""
    keep = np.arange(0, poses.n_frames, KEEP_EVERY)
    out = np.setdiff1d(np.arange(keep[-1] + 1), keep)
    sub = make_poses(poses.vertices[keep], poses.faces, poses.times[keep])
    clip = decode(fit_poses(sub, FitOptions(target_rel_rms=target, time_model=model, best_effort=True)))
    times = np.asarray(poses.times, np.float64)
    t = (times[out] - times[keep[0]]) / (times[keep[-1]] - times[keep[0]])
    diag = bbox_diagonal(poses.vertices[0])
    truth = poses.vertices[out]
    kept = poses.vertices[keep].astype(np.float64)
    return {"clip": rel_rms(clip.evaluate(t), truth, diag),
            "linear": rel_rms(linear_interpolation(times[keep], kept, times[out]), truth, diag),
            "catmull_rom": rel_rms(catmull_rom_interpolation(times[keep], kept, times[out]), truth, diag)}


def row(name: str, poses: Poses, model: str, target: float) -> dict:
    """One fit's figures."""
    start = time.perf_counter()
    parts = fit_poses(poses, FitOptions(target_rel_rms=target, time_model=model))
    seconds = time.perf_counter() - start
    r = parts.report
    h = heldout(poses, model, target)
    size = len(parts.topology) + len(parts.coefficients)
    return {"sequence": name, "target": target, "model": model, "bytes": size,
            "rms": r["rel_rms"] / target, "max": r["rel_max"] / target, "met": r["target_met"],
            "segments": r["segments"], **r["time_models"], "seconds": seconds,
            "held_clip": h["clip"], "held_vs_linear": h["clip"] / h["linear"],
            "held_vs_cr": h["clip"] / h["catmull_rom"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--targets", default="3e-3,1e-3")
    ap.add_argument("--sequences", default=",".join(NAMES))
    ap.add_argument("--quick", action="store_true", help="two short sequences at 3e-3")
    args = ap.parse_args()
    names = ["AnimatedMorphSphere", "horse-collapse"] if args.quick else args.sequences.split(",")
    targets = [3e-3] if args.quick else [float(x) for x in args.targets.split(",")]
    print(f"# time models, {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
          f"load {os.getloadavg()[0]:.1f}")
    print("| sequence | target | time model | bytes | rms/target | max/target | segments | spline | pde "
          "(constant) | pde (linear) | held-out rel-RMS | / linear | / Catmull-Rom |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        poses = load(name)
        for target in targets:
            for model in MODELS:
                r = row(name, poses, model, target)
                print(f"| {name} | {target:g} | {model} | {r['bytes']:,} | {r['rms']:.2f} | {r['max']:.2f} | "
                      f"{r['segments']} | {r['spline']} | {r['pde']} | {r['linear']} | "
                      f"{r['held_clip']:.2e} | {r['held_vs_linear']:.3f} | {r['held_vs_cr']:.3f} |",
                      flush=True)
    print(f"# done, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
