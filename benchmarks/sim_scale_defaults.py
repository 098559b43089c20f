"""Default scene on one mesh at several scales: does the default material give visible, stable motion whatever
the mesh's units? Spot (tests/data/spot.obj) scaled to bounding-box diagonals 0.15, 1.5 and 15, simulated
with the default SceneParams (60 frames at 30 fps, 3000 tets); prints substeps (and whether the cap bound),
Young's modulus used, seconds, and the largest displacement relative to the diagonal, with the load average.
Run: .venv/bin/python benchmarks/sim_scale_defaults.py
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from pdeanim.mesh.io import SurfaceMesh, load_mesh
from pdeanim.sim.scene import SceneParams
from pdeanim.sim.simulate import simulate_mesh

SPOT = Path(__file__).resolve().parents[1] / "tests" / "data" / "spot.obj"


def main() -> None:
    base = load_mesh(SPOT)
    for diagonal in (0.15, 1.5, 15.0):
        mesh = SurfaceMesh(base.vertices * (diagonal / base.diagonal()), base.faces)
        started = time.perf_counter()
        poses = simulate_mesh(mesh, SceneParams(frames=60))
        seconds = time.perf_counter() - started
        moved = float(np.linalg.norm(poses.vertices - poses.vertices[:1], axis=2).max())
        m = poses.meta
        print(f"diagonal {diagonal:>6}: young {m.get('young', m['scene'].get('young'))!s:>10}, substeps "
              f"{m['substeps']}{' (capped)' if m['substeps_capped'] else ''}, {seconds:.1f} s, "
              f"max displacement {100 * moved / diagonal:.2f}% of the diagonal, "
              f"finite {bool(np.isfinite(poses.vertices).all())}, "
              f"load {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
