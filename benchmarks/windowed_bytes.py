"""Bytes of a fit in windows of frames against the one-piece fit (issue 21: at most 5% more), on the shared
sequences: each sequence fitted with the CLI's defaults, then forced into W windows of frames (the windowed
path that long inputs take on their own) at the same target.

    .venv/bin/python benchmarks/windowed_bytes.py [--windows 4] [--targets 3e-3] [--sequences a,b]

Sequences are read from ../shared/data/sequences (benchmarks only)."""

from __future__ import annotations

import argparse
import datetime
import os
import time
from dataclasses import replace

from time_models import NAMES, load

from pdeanim.fit import FitOptions, fit_poses
from pdeanim.fit.options import FitTolerances


def fit_row(name: str, target: float, windows: int) -> dict:
    """One-piece and windowed fits of one sequence at ``target``: bytes, errors and seconds of each."""
    poses = load(name)
    options = FitOptions(target_rel_rms=target)
    out = {"sequence": name, "frames": poses.n_frames, "vertices": poses.n_vertices, "target": target}
    forced = replace(FitTolerances(), window_fit_values=0,
                     window_values=-(-poses.n_frames // windows) * poses.n_vertices)
    for label, tol in (("one-piece", FitTolerances()), ("windowed", forced)):
        start = time.perf_counter()
        parts = fit_poses(poses, options, tolerances=tol)
        r = parts.report
        out[label] = {"bytes": len(parts.topology) + len(parts.coefficients), "rms": r["rel_rms"] / target,
                      "max": r["rel_max"] / target, "met": r["target_met"],
                      "seconds": time.perf_counter() - start}
    return out


def cell(fit: dict) -> str:
    """bytes (RMS as a share of the target, max as a multiple of it)."""
    return f"{fit['bytes']:,} ({fit['rms']:.2f}, {fit['max']:.1f}x)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--windows", type=int, default=4)
    ap.add_argument("--targets", default="3e-3")
    ap.add_argument("--sequences", default=",".join(NAMES))
    args = ap.parse_args()
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(f"# windowed vs one-piece, {args.windows} windows, {now}, load {os.getloadavg()[0]:.1f}")
    print("| sequence | frames x vertices | target | one-piece bytes (rms, max x target) | windowed bytes "
          "(rms, max x target) | windowed / one-piece | met |")
    print("|---|---|---|---|---|---|---|")
    for target in (float(t) for t in args.targets.split(",")):
        for name in args.sequences.split(","):
            r = fit_row(name, target, args.windows)
            a, b = r["one-piece"], r["windowed"]
            met = "yes" if a["met"] and b["met"] else "NO"
            print(f"| {name} | {r['frames']} x {r['vertices']:,} | {target:g} | {cell(a)} | {cell(b)} | "
                  f"{b['bytes'] / a['bytes']:.3f} | {met} |", flush=True)
    print(f"# done, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
