"""Bytes of a fit in windows of frames against the one-piece fit (issue 31: at most 1.05x), on the shared
sequences: each sequence fitted with the CLI's defaults, then forced into 2, 4 and 8 windows of frames (the
windowed path that long inputs take on their own) at the same target. Every clip's errors are measured on
its decoded frames (not taken from its report): rel-RMS must meet the target and rel-max stay within 3x it.

    .venv/bin/python benchmarks/windowed_bytes.py [--windows 2,4,8] [--targets 3e-3] [--sequences a,b]

Sequences are read from ../shared/data/sequences (benchmarks only)."""

from __future__ import annotations

import argparse
import datetime
import os
import time
from dataclasses import replace

import numpy as np
from time_models import NAMES, load

from pdeanim.clip import load_clip
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.fit.options import FitTolerances
from pdeanim.poses import Poses

GOAL_BYTES = 1.05
"""A windowed clip at most this multiple of the one-piece clip's bytes (issue 31)."""
GOAL_MAX = 3.0
"""Its max error at most this multiple of the RMS target, as the one-piece fit's soft bound."""


def forced(poses: Poses, windows: int) -> FitTolerances:
    """Tolerances that fit ``poses`` in ``windows`` windows of frames."""
    return replace(FitTolerances(), window_fit_values=0,
                   window_values=-(-poses.n_frames // windows) * poses.n_vertices)


def measured(poses: Poses, options: FitOptions, tol: FitTolerances, target: float) -> dict:
    """One fit: bytes, decoded rel-RMS and rel-max over the target, segments, windows, seconds."""
    start = time.perf_counter()
    parts = fit_poses(poses, options, tolerances=tol)
    seconds = time.perf_counter() - start
    r = parts.report
    clip = load_clip(parts.topology, parts.coefficients)
    d = np.linalg.norm(clip.evaluate(clip.frame_t()).astype(np.float64) - poses.vertices, axis=-1)
    diag = r["diagonal"]
    return {"bytes": len(parts.topology) + len(parts.coefficients),
            "rms": float(np.sqrt(np.mean(d * d))) / diag / target, "max": float(d.max()) / diag / target,
            "segments": r["segments"], "windows": len(r.get("windows") or [None]),
            "rank": r.get("knot_rank"), "seconds": seconds}


def cell(fit: dict) -> str:
    """bytes (RMS as a share of the target, max as a multiple of it; segments)."""
    return f"{fit['bytes']:,} ({fit['rms']:.2f}, {fit['max']:.2f}x; S={fit['segments']})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--windows", default="2,4,8")
    ap.add_argument("--targets", default="3e-3")
    ap.add_argument("--sequences", default=",".join(NAMES))
    args = ap.parse_args()
    counts = [int(w) for w in args.windows.split(",")]
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(f"# windowed vs one-piece, windows {counts}, {now}, load {os.getloadavg()[0]:.1f}")
    print(f"# goals: windowed bytes <= {GOAL_BYTES}x one-piece; decoded rel-RMS <= target; rel-max <= "
          f"{GOAL_MAX}x target")
    print("| sequence | frames x vertices | target | one-piece bytes (rms, max x target; segments) | "
          "windows | windowed bytes (rms, max x target; segments) | windowed / one-piece | bytes goal | "
          "errors goal |")
    print("|---|---|---|---|---|---|---|---|---|")
    missed = 0
    for target in (float(t) for t in args.targets.split(",")):
        for name in args.sequences.split(","):
            poses = load(name)
            options = FitOptions(target_rel_rms=target)
            whole = measured(poses, options, FitTolerances(), target)
            for W in counts:
                part = measured(poses, options, forced(poses, W), target)
                ratio = part["bytes"] / whole["bytes"]
                ok_bytes = ratio <= GOAL_BYTES
                ok_err = all(f["rms"] <= 1.0 and f["max"] <= GOAL_MAX for f in (whole, part))
                missed += (not ok_bytes) + (not ok_err)
                print(f"| {name} | {poses.n_frames} x {poses.n_vertices:,} | {target:g} | {cell(whole)} | "
                      f"{part['windows']} | {cell(part)} | {ratio:.3f} | "
                      f"{'met' if ok_bytes else 'NOT met'} | {'met' if ok_err else 'NOT met'} |", flush=True)
    print(f"# done, load {os.getloadavg()[0]:.1f}; {missed} goal(s) NOT met")


if __name__ == "__main__":
    main()
