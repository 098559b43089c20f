"""Fit speed: 600 curves x 100 frames (25 points per curve, 15k vertices). Target < 0.2 s (2-core machine).

The headline is the whole ``fit_poses`` call (preparation, space and time stages, encoding, decoding and
evaluating every frame to report errors honestly), median of several runs. The two internal stages on
prepared data are printed too, as a breakdown, not as the fit time.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from model_common import ring_curves, torus_poses  # noqa: E402

from pdeanim.fit import FitOptions, fit_poses  # noqa: E402
from pdeanim.fit.problem import prepare  # noqa: E402
from pdeanim.model.fitcore import space_stage, time_stage  # noqa: E402
from pdeanim.model.segments import uniform_segmentation  # noqa: E402


def main(repeats: int = 5) -> None:
    poses = torus_poses(150, 100, 100)
    curves = ring_curves(150, 100)
    opts = FitOptions(segments=4)
    p = prepare(poses, opts, curves)
    K, N = p.Y.shape[1], p.Y.shape[2]
    mask = np.repeat(p.mask, 3, axis=0)
    spaces, times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sp = space_stage(p.Y, p.u.reshape(K, N), mask)
        t1 = time.perf_counter()
        time_stage(sp, uniform_segmentation(p.t, 4))
        t2 = time.perf_counter()
        spaces.append(t1 - t0)
        times.append(t2 - t1)
    totals, adaptive = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        parts = fit_poses(poses, opts, curves=curves)
        totals.append(time.perf_counter() - t0)
    for _ in range(max(3, repeats // 2)):
        t0 = time.perf_counter()
        fit_poses(poses, FitOptions(target_rel_rms=1e-3), curves=curves)
        adaptive.append(time.perf_counter() - t0)
    r = parts.report
    def ms(v: list[float]) -> str:
        return f"{np.median(v) * 1e3:.0f} ms (min {min(v) * 1e3:.0f}, max {max(v) * 1e3:.0f})"

    fit = np.array(spaces) + np.array(times)
    print(f"{curves.n_curves} curves x {poses.n_frames} frames ({poses.n_vertices} vertices), 4 segments; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"whole fit_poses call: {ms(totals)} (median of {repeats}; target 200 ms); "
          f"rel rms {r['rel_rms']:.2e}, "
          f"coefficients {len(parts.coefficients)} bytes")
    print(f"  of which space stage {ms(spaces)} + time stage {ms(times)} = {ms(fit)} on prepared data")
    print(f"with target rel rms 1e-3 (adaptive segments): {ms(adaptive)} (median of {len(adaptive)})")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
