"""Print how still planted feet stay, per gait and rig: the test rigs built in code (biped, quadruped with
three-bone hind legs, hexapod; and shapes of real exports: "sloped" paws with Blender names, "controlled"
paws bound to IK control bones at the root, a "plantigrade" biped with Mixamo names and toe bones), the
public Fox (tests/data/Fox.glb, CC BY 4.0), and any skinned glTF/GLB paths given (every gait of its leg
count, legs found from the skinned geometry, nothing named).

For every gait that fits a rig's legs, the cycle is measured twice in the ground's frame (positions plus the
root moved at the travel speed) on every sole vertex (each mesh vertex a leg moves within 2% of the mesh's
height of the ground at rest), in every frame it is down (within 1% of the leg of its rest height), planned
stance or not:
- "cycle": the skinned frames the generator makes (the exported GLB holds these);
- "clip": the looping dynamic-PDE clip fitted to them at each --targets relative RMS.
Figures, as percent of the mean leg length: slide (largest drift of a sole vertex from where it touched
down), height (largest distance of a sole vertex from its rest height in the planned stance), sink (deepest
a sole vertex goes below the ground); "down" is the least share of the cycle some vertex of a sole is down,
against the gait's duty; "phase" the largest gap (share of the cycle) between a sole's measured touch-down
and the gait table's; "miss" the IK's largest miss. Fit seconds are the median of --runs fits. A gait the
rig cannot do is printed with the reason.

Usage: python benchmarks/gaits.py [GLB ...] [--rigs biped,...,fox] [--frames 32] [--targets 1e-3,5e-4|none]
[--runs 3] [--pictures DIR]
(--pictures writes a strip of frames and the footfall diagram of every gait measured as PNG files; the dots
mark where each sole really is in the frames it is down.)
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

from dataclasses import replace  # noqa: E402

from pdeanim.cyclic.bodyplan import plan_of  # noqa: E402
from pdeanim.cyclic.contact import foot_figures  # noqa: E402
from pdeanim.cyclic.gaitclip import fit_gait_clip, skinned_offset, solve_gait  # noqa: E402
from pdeanim.cyclic.gaitplots import face_colours, gait_strip_png  # noqa: E402
from pdeanim.cyclic.gaits import GaitParams  # noqa: E402
from pdeanim.errors import PdeanimError  # noqa: E402
from pdeanim.gltf.skin import load_skinned  # noqa: E402
from tests.cyclic.rig import (  # noqa: E402
    BIPED,
    CONTROLLED,
    HEXAPOD,
    PLANTIGRADE,
    QUADRUPED,
    SLOPED,
    rig_glb,
)

QUAD = ("walk", "trot", "pace", "canter", "gallop")
RIGS = {"biped": BIPED, "quadruped": QUADRUPED, "hexapod": HEXAPOD, "sloped": SLOPED,
        "controlled": CONTROLLED, "plantigrade": PLANTIGRADE}
BUILT_IN = (*RIGS, "fox")


def gaits_of(data: bytes) -> tuple[str, ...]:
    """Every gait of the character's leg count (legs found from its skinned geometry)."""
    n = len(plan_of(load_skinned(data)).legs)
    return ("walk", "run") if n == 2 else QUAD if n == 4 else ("tripod", "wave")


def sources(names: list[str], paths: list[Path]) -> dict[str, bytes]:
    """The GLB bytes of every rig named and of every path given (named by its file stem)."""
    out = {name: rig_glb(RIGS[name]) for name in names if name in RIGS}
    if "fox" in names:
        out["fox"] = (ROOT / "tests" / "data" / "Fox.glb").read_bytes()
    for path in paths:
        out[path.stem] = path.read_bytes()
    return out


def phase_gap(result) -> float:
    """The largest gap (share of the cycle) between a sole's measured touch-down and its gait table phase."""
    cyc, plan = result.cycle, result.cycle.plan
    k, worst = len(cyc.times) - 1, 0.0
    for i, sole in enumerate(result.soles):
        down = foot_figures(result.poses.vertices, cyc.times, cyc.params.period, cyc.paths.stance[:, i], sole,
                            cyc.speed, plan.axes.forward, plan.axes.up, plan.leg_length)["down"]
        landing = np.flatnonzero(down & ~np.roll(down, 1))
        if len(landing) != 1:
            return float("nan")  # no single touch-down: the sole never lifts, or lands twice
        gap = abs(landing[0] / k - cyc.phases[i])
        worst = max(worst, min(gap, 1 - gap))
    return worst


def pct(x: float) -> str:
    return f"{100 * x:.3g}"


def measure(name: str, data: bytes, gait: str, frames: int, targets: list[float], runs: int,
            pictures: Path | None) -> list[str]:
    """One table row per target: the cycle's figures and the fitted clip's."""
    try:
        result = solve_gait(data, GaitParams.preset(gait), frames)
    except PdeanimError as exc:
        return [f"{name} | {gait} | refused: {exc}"]
    c, cyc = result.report["contact"], result.cycle
    unit = c["leg_length"]
    soles = sum(x["vertices"] for x in c["legs"])
    head = [name, gait, str(len(cyc.plan.legs)), str(soles), f"{cyc.duty:.2f}", f"{cyc.speed / unit:.3g}",
            pct(c["slide_max_rel"]), pct(c["stance_height_max_rel"]),
            pct(c["sink_max_rel"]), f"{c['down_share_min']:.2f}", f"{phase_gap(result):.3f}",
            f"{float(cyc.miss.max()) / unit:.1e}"]
    rows = [] if targets else [" | ".join(head)]
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
    if pictures is not None:
        skinned = load_skinned(data)
        start = skinned_offset(data)
        own = result.poses.vertices[:, start:start + len(skinned.rest_vertices)]
        soles = [replace(s, vertices=s.vertices - start) for s in result.soles]
        gait_strip_png(pictures / f"{name}-{gait}.png", own, skinned.faces,
                       face_colours(data, len(skinned.faces)), cyc, soles=soles,
                       title=f"{name}: {gait} (soles slide {pct(c['slide_max_rel'])}%, sink "
                             f"{pct(c['sink_max_rel'])}% of the leg)")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=32, help="frames per cycle")
    ap.add_argument("paths", nargs="*", type=Path, help="skinned glTF/GLB files to measure as well")
    ap.add_argument("--targets", default="1e-3,5e-4",
                    help="fit targets (relative RMS), comma-separated, or none (the cycle only)")
    ap.add_argument("--runs", type=int, default=3, help="fits per target (median time)")
    ap.add_argument("--pictures", type=Path, help="write the strip pictures into this folder")
    ap.add_argument("--rigs", default=",".join(BUILT_IN),
                    help=f"built-in rigs to measure, comma-separated ({', '.join(BUILT_IN)}), or none")
    args = ap.parse_args()
    targets = [] if args.targets == "none" else [float(x) for x in args.targets.split(",")]
    names = [] if args.rigs == "none" else args.rigs.split(",")
    unknown = set(names) - set(BUILT_IN)
    if unknown:
        ap.error(f"unknown rigs: {', '.join(sorted(unknown))} (known: {', '.join(BUILT_IN)})")
    if args.pictures is not None:
        args.pictures.mkdir(parents=True, exist_ok=True)
    print(f"# gaits benchmark, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPUs, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {args.frames} frames per cycle")
    print("rig | gait | legs | sole vertices | duty | speed (legs/s) | cycle slide % | cycle height % | "
          "cycle sink % | down | phase gap | IK miss (leg)"
          + (" | target | clip rel RMS | clip slide % | clip height % | clip sink % | coef bytes | fit s"
             if targets else ""))
    print("|".join(["---"] * (19 if targets else 12)))
    data = sources(names, args.paths)
    for name in data:
        try:
            gaits = gaits_of(data[name])
        except PdeanimError as exc:
            print(f"{name} | - | refused: {exc}", flush=True)
            continue
        for gait in gaits:
            for line in measure(name, data[name], gait, args.frames, targets, args.runs, args.pictures):
                print(line, flush=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
