"""Tetrahedralization time of large meshes at the default tet budget (3000 tets), uncached.

Meshes: trimesh icospheres subdivided 6 and 7 times (40,962 and 163,842 vertices) with 2% radial noise, like
a scan. Each mesh is decimated to the tet budget's surface (``pdeanim.sim.tetra.surface_budget``) and handed
to fTetWild in a child process, as ``pdeanim simulate`` and the worker do. Prints the median of several runs
and the load average (the machine may be shared).
``--before`` measures the former pipeline for comparison in the same conditions: vertex clustering (no
quadric decimation) to a fixed 20,000-face budget.
Run: .venv/bin/python benchmarks/tetrahedralize_large.py [--runs N] [--before]
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np
import trimesh

from pdeanim.mesh.io import SurfaceMesh
from pdeanim.sim import decimate as decimation
from pdeanim.sim import tetra
from pdeanim.sim.tetra import TetParams, surface_budget, tetrahedralize


def former_surface(mesh: SurfaceMesh, params: TetParams) -> tuple[np.ndarray, np.ndarray]:
    """The surface the former pipeline handed to fTetWild: clustered to at most max_surface_faces."""
    quadric = decimation.quadric_decimate
    decimation.quadric_decimate = lambda *args: None
    try:
        return decimation.decimate(mesh.vertices, mesh.faces, params.max_surface_faces)
    finally:
        decimation.quadric_decimate = quadric


def noisy_sphere(subdivisions: int) -> SurfaceMesh:
    m = trimesh.creation.icosphere(subdivisions)
    scale = 1 + 0.02 * np.random.default_rng(0).standard_normal(len(m.vertices))
    return SurfaceMesh(np.asarray(m.vertices) * scale[:, None], np.asarray(m.faces, np.int64))


def main(runs: int) -> None:
    params = TetParams(target_tets=3000)
    budget = surface_budget(params.target_tets, params.max_surface_faces)
    print(f"target tets {params.target_tets}, surface budget {budget} "
          f"faces, fTetWild threads {params.threads}")
    for sub in (6, 7):
        mesh = noisy_sphere(sub)
        seconds, tets = [], []
        for _ in range(runs):
            started = time.perf_counter()
            result = tetrahedralize(mesh, params)  # no cache_dir: every run tetrahedralizes
            seconds.append(time.perf_counter() - started)
            tets.append(result.n_tets)
        print(f"{len(mesh.vertices):>7} vertices {len(mesh.faces):>7} faces: "
              f"median {statistics.median(seconds):.2f} s "
              f"(runs {', '.join(f'{s:.2f}' for s in seconds)}), tets {tets}, load {os.getloadavg()}")


if __name__ == "__main__":
    if "--before" in sys.argv:
        tetra.tet_surface = former_surface
        print("FORMER pipeline (clustering to 20,000 faces)")
    main(int(sys.argv[sys.argv.index("--runs") + 1]) if "--runs" in sys.argv else 3)
