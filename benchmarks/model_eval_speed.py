"""Evaluation speed of a dynamic-PDE clip: one frame of 15k vertices (target < 0.2 ms), median of many."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from model_common import ring_curves, torus_poses  # noqa: E402

from pdeanim.clip import load_clip  # noqa: E402
from pdeanim.fit import FitOptions, fit_poses  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--time-model", choices=["auto", "pde", "spline"], default="auto",
                    help="time model of the fit (default: the fit's, auto)")
    args = ap.parse_args()
    poses = torus_poses(150, 100, 40)
    options = FitOptions(segments=4, time_model=args.time_model)
    parts = fit_poses(poses, options, curves=ring_curves(150, 100))
    clip = load_clip(parts.topology, parts.coefficients)
    rng = np.random.default_rng(0)
    ts = rng.uniform(0, 1, 2000)
    for t in ts[:50]:
        clip.evaluate(float(t))
    samples = []
    for t in ts:
        t0 = time.perf_counter()
        clip.evaluate(float(t))
        samples.append(time.perf_counter() - t0)
    s = np.array(samples) * 1e3
    print(f"vertices {clip.n_vertices}, curves {clip.info()['n_curves']}, segments "
          f"{clip.info()['n_segments']}, format {parts.report['format_version']}, time models of the curve "
          f"coordinates {parts.report['time_models']}")
    print(f"evaluate one frame: median {np.median(s):.4f} ms, p10 {np.percentile(s, 10):.4f} ms, "
          f"p90 {np.percentile(s, 90):.4f} ms over {len(s)} frames (target < 0.2 ms; shared 2-core machine, "
          f"load average {os.getloadavg()[0]:.1f})")
    t0 = time.perf_counter()
    clip.evaluate(np.linspace(0, 1, 100))
    print(f"evaluate 100 frames in one call: {(time.perf_counter() - t0) * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
