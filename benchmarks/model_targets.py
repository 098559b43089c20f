"""AnimatedMorphSphere (216 frames x 1876 vertices) at several relative RMS targets: achieved RMS and max,
bytes of both parts and the ratio to raw float32, fit time, and the held-out-frame comparison (fit every
3rd frame, evaluate the frames left out, against linear interpolation of the same kept frames).
Curves come from the default extraction (shortened automatically until the spatial floor leaves room).
Timings on a shared, loaded 2-core machine.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from pdeanim.fit import FitOptions, fit_poses
from pdeanim.fit.heldout import heldout_comparison
from pdeanim.posefiles import load_poses

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "AnimatedMorphSphere.npz"
TARGETS = (1e-2, 3e-3, 1e-3)


def main() -> None:
    poses = load_poses(DATA)
    print(
        f"AnimatedMorphSphere: {poses.n_frames} frames x {poses.n_vertices} vertices, raw float32 "
        f"{poses.n_frames * poses.n_vertices * 12} bytes; fit s = median of 3 runs; load average "
        f"{os.getloadavg()[0]:.1f}"
    )
    print(
        f"{'target':>8s} {'rel rms':>9s} {'rel max':>9s} {'rms':>9s} {'max':>9s} {'curves':>6s} {'segs':>5s} "
        f"{'topo B':>8s} {'coef B':>8s} {'coef/raw':>9s} {'all/raw':>8s} {'fit s':>6s}"
    )
    for target in TARGETS:
        runs = []
        for _ in range(3):  # deterministic: every run gives the same clip; the time is the median
            t0 = time.perf_counter()
            parts = fit_poses(poses, FitOptions(target_rel_rms=target))
            runs.append(time.perf_counter() - t0)
        dt = float(np.median(runs))
        r, s = parts.report, parts.report["sizes"]
        print(f"{target:8.0e} {r['rel_rms']:9.2e} {r['rel_max']:9.2e} {r['rms']:9.2e} {r['max']:9.2e} "
              f"{r['curves']:6d} {r['segments']:5d} {s['topology_bytes']:8d} {s['coefficients_bytes']:8d} "
              f"{s['ratio_coefficients_to_raw']:9.4f} {s['ratio_total_to_raw']:8.4f} {dt:6.2f}")
    print("\nheld-out frames (fit on every 3rd frame + last, evaluate the others):")
    print(f"{'target':>8s} {'kept':>5s} {'held':>5s} {'PDE rel rms':>12s} {'PDE rel max':>12s} "
          f"{'linear rel rms':>15s} {'linear rel max':>15s} {'coef B':>8s} {'kept raw B':>11s} "
          f"{'lin@same bytes rel rms (frames)':>32s}")
    for target in TARGETS:
        h = heldout_comparison(poses, 3, FitOptions(target_rel_rms=target))
        print(f"{target:8.0e} {h['kept_frames']:5d} {h['heldout_frames']:5d} {h['pde']['rel_rms']:12.2e} "
              f"{h['pde']['rel_max']:12.2e} {h['linear']['rel_rms']:15.2e} {h['linear']['rel_max']:15.2e} "
              f"{h['coefficients_bytes']:8d} {h['kept_raw_bytes']:11d} "
              f"{h['linear_equal_bytes']['rel_rms']:24.2e} ({h['linear_equal_bytes_frames']})")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
