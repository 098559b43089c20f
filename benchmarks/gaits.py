"""Print how still planted feet stay, per gait and rig: the test rigs built in code (biped, quadruped with
three-bone hind legs, hexapod) and the public Fox (tests/data/Fox.glb, CC BY 4.0).

For every gait that fits a rig's legs, the cycle is measured twice in the ground's frame (positions plus the
root moved at the travel speed), on each foot's sole (its lowest mesh vertices bound to the foot):
- "cycle": the skinned frames the generator makes (the exported GLB holds these);
- "clip": the looping dynamic-PDE clip fitted to them at each --targets relative RMS.
Figures, as percent of the mean leg length: slide (largest drift of a planted sole), height (largest
distance of a planted sole from its rest height), sink (deepest a sole goes below the ground); "down" is
the least share of the cycle any sole is within 1% of the leg of the ground against the gait's duty; "miss"
the IK's largest miss. Fit seconds are the median of --runs fits.

Usage: python benchmarks/gaits.py [--frames 32] [--targets 1e-3,5e-4] [--runs 3] [--pictures DIR]
(--pictures writes a strip of frames and the footfall diagram of every gait of the biped, the hexapod and the
fox as PNG files.)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pdeanim.cyclic.gaitclip import fit_gait_clip, skinned_offset, solve_gait  # noqa: E402
from pdeanim.cyclic.gaitplots import face_colours, gait_strip_png  # noqa: E402
from pdeanim.cyclic.gaits import GaitParams  # noqa: E402
from pdeanim.gltf.skin import load_skinned  # noqa: E402
from tests.cyclic.rig import BIPED, HEXAPOD, QUADRUPED, rig_glb  # noqa: E402

GAITS = {"biped": ("walk", "run"), "quadruped": ("walk", "trot", "pace", "canter", "gallop"),
         "hexapod": ("tripod", "wave"), "fox": ("walk", "trot", "pace", "canter", "gallop")}
PICTURED = ("biped", "hexapod", "fox")  # the quadruped rig's gaits are pictured by the fox's


def sources() -> dict[str, bytes]:
    """The GLB bytes of every rig."""
    out = {name: rig_glb(rig) for name, rig in (("biped", BIPED), ("quadruped", QUADRUPED),
                                                ("hexapod", HEXAPOD))}
    out["fox"] = (ROOT / "tests" / "data" / "Fox.glb").read_bytes()
    return out


def pct(x: float) -> str:
    return f"{100 * x:.3g}"


def measure(name: str, data: bytes, gait: str, frames: int, targets: list[float], runs: int,
            pictures: Path | None) -> list[str]:
    """One table row per target: the cycle's figures and the fitted clip's."""
    result = solve_gait(data, GaitParams.preset(gait), frames)
    c, cyc = result.report["contact"], result.cycle
    unit = c["leg_length"]
    head = [name, gait, str(len(cyc.plan.legs)), f"{cyc.duty:.2f}", f"{cyc.speed / unit:.3g}",
            pct(c["slide_max_rel"]), pct(c["stance_height_max_rel"]), pct(c["sink_max_rel"]),
            f"{c['down_share_min']:.2f}", f"{float(cyc.miss.max()) / unit:.1e}"]
    rows = []
    for target in targets:
        times, parts = [], None
        for _ in range(runs):
            start = time.perf_counter()
            parts = fit_gait_clip(result, target)
            times.append(time.perf_counter() - start)
        k = parts.report["contact_clip"]
        clip = [f"{target:g}", f"{parts.report['rel_rms']:.2e}", pct(k["slide_max_rel"]),
                pct(k["stance_height_max_rel"]), pct(k["sink_max_rel"]), str(len(parts.coefficients)),
                f"{np.median(times):.2f}"]
        rows.append(" | ".join([*head, *clip]))
    if pictures is not None and name in PICTURED:
        skinned = load_skinned(data)
        start = skinned_offset(data)
        own = result.poses.vertices[:, start:start + len(skinned.rest_vertices)]
        gait_strip_png(pictures / f"{name}-{gait}.png", own, skinned.faces,
                       face_colours(data, len(skinned.faces)), cyc, title=f"{name}: {gait}")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=32, help="frames per cycle")
    ap.add_argument("--targets", default="1e-3,5e-4", help="fit targets (relative RMS), comma-separated")
    ap.add_argument("--runs", type=int, default=3, help="fits per target (median time)")
    ap.add_argument("--pictures", type=Path, help="write the strip pictures into this folder")
    ap.add_argument("--rigs", default=",".join(GAITS), help="rigs to measure, comma-separated")
    args = ap.parse_args()
    targets = [float(x) for x in args.targets.split(",")]
    if args.pictures is not None:
        args.pictures.mkdir(parents=True, exist_ok=True)
    print(f"# gaits benchmark, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPUs, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {args.frames} frames per cycle")
    print("rig | gait | legs | duty | speed (legs/s) | cycle slide % | cycle height % | cycle sink % | "
          "down | IK miss (leg) | target | clip rel RMS | clip slide % | clip height % | clip sink % | "
          "coef bytes | fit s")
    print("|".join(["---"] * 17))
    data = sources()
    for name in args.rigs.split(","):
        for gait in GAITS[name]:
            for line in measure(name, data[name], gait, args.frames, targets, args.runs, args.pictures):
                print(line, flush=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
