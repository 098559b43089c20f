"""Print the cyclic-animation table: for each generated body (tests/data/fish_*.obj) the number of boundary
curves, coefficient bytes against the mesh, the PDE surface's distance to the mesh at rest (mean and max,
relative to the bounding-box diagonal), build time and frames per second of evaluation.

Usage: python benchmarks/cyclic_table.py [--mode trout] [--pictures DIR]
(--pictures writes a spine picture and swim-cycle frames of each body as PNG files.)
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from pdeanim.clip import load_clip
from pdeanim.cyclic.body import body_frame, cut_body
from pdeanim.cyclic.chain import BodySurface
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.cyclic.plots import plot_body_spine, plot_swim_frames
from pdeanim.mesh.io import load_mesh

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
BODIES = ["fish_capsule", "fish_trout", "fish_eel"]


def fps(clip: object, batch: int) -> float:
    """Frames evaluated per second, in batches of the given size (median of seven)."""
    t = np.linspace(0.0, 1.0, batch, endpoint=False)
    runs = []
    for _ in range(7):
        start = time.perf_counter()
        clip.evaluate(t if batch > 1 else 0.37)
        runs.append(time.perf_counter() - start)
    return batch / float(np.median(runs))


def row(name: str, mode: str, pictures: Path | None) -> dict:
    """Build the clip of one body and measure it."""
    mesh = load_mesh(DATA / f"{name}.obj")
    start = time.perf_counter()
    parts = make_cyclic_clip(mesh, CyclicOptions(mode=mode))
    build = time.perf_counter() - start
    clip = load_clip(parts.topology, parts.coefficients)
    r = parts.report
    if pictures is not None:
        frame = body_frame(mesh.vertices)
        curves = cut_body(mesh.vertices, mesh.faces, frame, r["curves"], r["points"]).curves
        spine = BodySurface.from_curves(curves, modes=r["modes"]).spine.polyline()
        plot_body_spine(pictures / f"{name}_spine.png", mesh.vertices, mesh.faces, frame, spine, curves)
        plot_swim_frames(pictures / f"{name}_{mode}_frames.png", clip, np.linspace(0.0, 1.0, 7)[:-1])
        plot_swim_frames(pictures / f"{name}_{mode}_surface.png", clip, np.linspace(0.0, 1.0, 7)[:-1],
                         surface=True)
    return {"body": name, "V": len(mesh.vertices), "curves": r["curves"], "coef_B": len(parts.coefficients),
            "topo_B": len(parts.topology), "mesh_B": r["mesh_bytes"],
            "cycle_raw_B": r["sizes"]["raw_float32_bytes"], "rel_mean": r["rest_distance"]["rel_mean"],
            "rel_max": r["rest_distance"]["rel_max"], "build_s": build, "fps_1": fps(clip, 1),
            "fps_240": fps(clip, 240)}


def main() -> None:
    """Print the table (and optionally write pictures)."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mode", default="trout")
    parser.add_argument("--pictures", type=Path)
    args = parser.parse_args()
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
    rows = [row(name, args.mode, args.pictures) for name in BODIES]
    head = (f"{'body':<13}{'V':>6}{'curves':>7}{'coef B':>8}{'topo B':>8}{'mesh B':>8}{'cycle raw B':>12}"
            f"{'rest mean':>10}{'rest max':>10}{'build s':>8}{'fps(1)':>9}{'fps(240)':>10}")
    print(f"mode {args.mode}; rest distance = mesh vertex to PDE surface / bbox diagonal; "
          "raw = 25 frames float32; "
          f"load average {os.getloadavg()[0]:.1f}")
    print(head)
    for r in rows:
        print(f"{r['body']:<13}{r['V']:>6}{r['curves']:>7}{r['coef_B']:>8}{r['topo_B']:>8}{r['mesh_B']:>8}"
              f"{r['cycle_raw_B']:>12}{r['rel_mean']:>10.2e}{r['rel_max']:>10.2e}{r['build_s']:>8.2f}"
              f"{r['fps_1']:>9.0f}{r['fps_240']:>10.0f}")


if __name__ == "__main__":
    main()
