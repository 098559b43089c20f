"""Our XPBD solver side by side with pypbd 2.2.2 (the engine of paper 000): speed, a Table-1-like table, and
cantilever tip deflection at three resolutions. Prints the figures.

Run in the benchmark venv (pypbd installed there only):
    python3 -m venv .venv-bench
    .venv-bench/bin/pip install pypbd==2.2.2 numpy trimesh pytetwild==0.2.3 -e .
    .venv-bench/bin/python benchmarks/sim_compare.py [--part speed|table|deflection|all] [--quick]
Both engines run on the same tet mesh with pypbd's defaults: h = 0.005 s, 5 substeps, 1 iteration (our
substep is h / 5), single-threaded (ours also on 2 threads). pypbd runs FEM-based PBD (its default solid
method) in a child process. On a shared machine the 2-thread figure needs the second core to be free.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "sim"))

from pdeanim.mesh.io import load_mesh  # noqa: E402
from pdeanim.sim import kernels  # noqa: E402
from pdeanim.sim.grid import box_tet_mesh  # noqa: E402
from pdeanim.sim.simulate import auto_substeps  # noqa: E402
from pdeanim.sim.tetmesh import TetMesh  # noqa: E402
from pdeanim.sim.tetra import TetParams, tetrahedralize  # noqa: E402
from pdeanim.sim.xpbd import Material, build_model, lumped_masses, rest_state, step  # noqa: E402

H, SUBSTEPS, ITERATIONS = 0.005, 5, 1
CACHE = ROOT / ".venv-bench" / "tet-cache"


def run_pypbd(mesh: TetMesh, fixed: np.ndarray, material: Material, steps: int, average: int = 1,
              substeps: int = SUBSTEPS) -> dict:
    """One pypbd run in a child process (single thread); returns final/mean positions and stepping seconds."""
    masses = lumped_masses(mesh, material.density)
    masses[fixed] = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(
            src,
            points=mesh.points,
            tets=mesh.tets,
            masses=masses,
            steps=steps,
            average=average,
            substeps=substeps,
            iterations=ITERATIONS,
            h=H,
            young=material.young,
            poisson=material.poisson,
        )
        env = dict(os.environ, OMP_NUM_THREADS="1")
        subprocess.run([sys.executable, str(Path(__file__).with_name("sim_pypbd.py")), str(src), str(dst)],
                       check=True, env=env, cwd=tmp)
        with np.load(dst) as out:
            return {k: out[k] for k in out.files}


def run_ours(mesh: TetMesh, fixed: np.ndarray, material: Material, dt: float, n: int, threads: int = 1,
             average: int = 1) -> dict:
    """Our solver for n substeps of dt; final and mean (over the last ``average``) positions and seconds."""
    kernels.set_threads(threads)
    model = build_model(mesh, material, (0.0, -9.81, 0.0), fixed)
    state, spare = rest_state(model), rest_state(model)
    step(model, state, spare, dt)  # compile outside the timing
    state, spare = rest_state(model), rest_state(model)
    mean = np.zeros_like(state.x)
    seconds = 0.0
    for s in range(n):
        started = time.perf_counter()
        step(model, state, spare, dt)
        seconds += time.perf_counter() - started
        state, spare = spare, state
        if s >= n - average:
            mean += state.x
    kernels.set_threads(1)
    return {"final": state.x, "mean": mean / average, "seconds": seconds, "colors": model.elements.n_colors}


def two_thread_bound(mesh: TetMesh, fixed: np.ndarray, material: Material, dt: float) -> float:
    """Sweep time on 2 free cores estimated from per-part CPU times (thread_time, robust to a busy machine):
    the slower of the two independent parts plus the tets between them, over the serial sweep time."""
    model = build_model(mesh, material, (0.0, -9.81, 0.0), fixed)
    e, state = model.elements, rest_state(model)
    args = (state.x, state.rot, state.rot, e.tets, e.cst, np.zeros((2, 0)), 1.0 / dt**2, e.offsets, e.chunks)
    bounds = [*e.parts, e.n_colors]
    if len(bounds) < 4:
        return 1.0
    buf = np.empty(kernels.ROWS * kernels.STRIDE)
    best = [np.inf] * (len(bounds) - 1)
    for _ in range(10):
        for i in range(len(bounds) - 1):
            started = time.thread_time()
            for _ in range(5):
                kernels._colours(*args, bounds[i], bounds[i + 1], buf)
            best[i] = min(best[i], time.thread_time() - started)
    return sum(best) / (max(best[:-1]) + best[-1])


def surface_tets(name: str, target: int) -> tuple[object, TetMesh]:
    """The shipped mesh and its (cached) fTetWild tets at about ``target`` tets."""
    mesh = load_mesh(ROOT / "tests" / "data" / f"{name}.obj")
    return mesh, tetrahedralize(mesh, TetParams(target_tets=target), cache_dir=CACHE)


def top_pins(mesh: TetMesh) -> np.ndarray:
    """Points in the top 10 % of the height: pinned in the speed and table runs."""
    y = mesh.points[:, 1]
    return np.flatnonzero(y > y.max() - 0.1 * np.ptp(y))


def speed(targets: list[int], repeats: int = 5) -> None:
    """us per tet per constraint sweep, both engines, same mesh, same substeps and iterations; medians of
    ``repeats`` interleaved runs (pypbd, ours on 1 thread, ours on 2 threads), with the load average seen."""
    material = Material(young=1e5, poisson=0.3, density=1000.0, damping=0.0)
    print(f"\n## Speed: us per tet per constraint sweep (h = 0.005, 5 substeps x 1 iteration), median of "
          f"{repeats}")
    print("| mesh | tets | colours | pypbd 1 thread | ours 1 thread | ratio pypbd/ours | ours 2 threads | "
          "2 threads speed-up | bound on 2 free cores | load avg |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in ("spot", "bob"):
        for target in targets:
            _, tets = surface_tets(name, target)
            fixed = top_pins(tets)
            steps = 40
            sweeps = steps * SUBSTEPS
            runs: list[list[float]] = [[], [], []]
            load = os.getloadavg()[0]
            for _ in range(repeats):
                ref = run_pypbd(tets, fixed, material, steps)
                ours = run_ours(tets, fixed, material, H / SUBSTEPS, sweeps)
                ours2 = run_ours(tets, fixed, material, H / SUBSTEPS, sweeps, threads=2)
                for r, run in zip(runs, (ref, ours, ours2), strict=True):
                    r.append(float(run["seconds"]) / sweeps / tets.n_tets * 1e6)
            per = [float(np.median(r)) for r in runs]
            bound = two_thread_bound(tets, fixed, material, H / SUBSTEPS)
            load = 0.5 * (load + os.getloadavg()[0])
            print(
                f"| {name} | {tets.n_tets} | {ours['colors']} | {per[0]:.3f} | {per[1]:.3f} | "
                f"{per[0] / per[1]:.2f} | {per[2]:.3f} | {per[1] / per[2]:.2f} | {bound:.2f} | {load:.1f} |",
                flush=True,
            )


def table(targets: list[int]) -> None:
    """Table-1-like: surface faces x tets x seconds for 100 frames at 30 fps (top 10 % pinned, gravity)."""
    material = Material(young=1e5, poisson=0.3, density=1000.0, damping=1.0)
    steps_per_frame = (1 / 30) / H
    print("\n## Table 1 analogue: 100 frames at 30 fps (h = 0.005 x 5 substeps unless 'auto')")
    print(
        "| mesh | surface faces | tets | fTetWild s | pypbd s | ours s (same steps) | ours auto "
        "substeps/frame | "
        "ours s (auto) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in ("spot", "bob"):
        for target in targets:
            surface = load_mesh(ROOT / "tests" / "data" / f"{name}.obj")
            started = time.perf_counter()
            tets = tetrahedralize(surface, TetParams(target_tets=target))  # uncached: the real cost
            tet_seconds = time.perf_counter() - started
            fixed = top_pins(tets)
            steps = int(round(100 * steps_per_frame))
            ref = run_pypbd(tets, fixed, material, steps)
            ours = run_ours(tets, fixed, material, H / SUBSTEPS, steps * SUBSTEPS)
            auto, _ = auto_substeps(tets, material, 1 / 30, 10_000)
            ours_auto = run_ours(tets, fixed, material, (1 / 30) / auto, 100 * auto)
            print(
                f"| {name} | {len(surface.faces)} | {tets.n_tets} | {tet_seconds:.1f} | "
                f"{float(ref['seconds']):.2f} "
                f"| {ours['seconds']:.2f} | {auto} | {ours_auto['seconds']:.2f} |",
                flush=True,
            )


def deflection(resolutions: list[int]) -> None:
    """Cantilever tip deflection / Euler-Bernoulli at three resolutions for both engines."""
    from fem_reference import static_displacement

    length, side, young, density = 0.5, 0.1, 2e7, 1000.0
    beam = density * 9.81 * side**2 * length**4 / (8 * young * side**4 / 12)
    material = Material(young=young, poisson=0.3, density=density, damping=100.0)
    print(f"\n## Cantilever 0.5 x 0.1 x 0.1 m, E = 20 MPa, nu = 0.3: tip deflection / Euler-Bernoulli "
          f"({beam:.5f} m)")
    print("| cells through thickness | tets | static linear FEM | pypbd (h=0.005, 5x1) | ours (same steps) | "
          "ours (auto substeps) | pypbd (our substeps) |")
    print("|---|---|---|---|---|---|---|")
    for n in resolutions:
        mesh = box_tet_mesh((length, side, side), (5 * n, n, n), split=5)
        fixed = np.flatnonzero(mesh.points[:, 0] < 1e-9)
        tip = mesh.points[:, 0] > length - 1e-9
        fem = static_displacement(mesh, young, 0.3, density, (0, -9.81, 0), fixed)

        def sag(x: np.ndarray, tip: np.ndarray = tip, mesh: TetMesh = mesh) -> float:
            return -(x[tip, 1] - mesh.points[tip, 1]).mean() / beam

        ref = run_pypbd(mesh, fixed, material, steps=600, average=200)  # 3 s, mean over the last second
        same = run_ours(mesh, fixed, material, H / SUBSTEPS, 600 * SUBSTEPS, average=200 * SUBSTEPS)
        auto, _ = auto_substeps(mesh, material, 0.15, 100_000)
        ours = run_ours(mesh, fixed, material, 0.15 / auto, auto)
        # pypbd has no damping: 0.6 s at our substep, deflection averaged over the last ~3 bending periods
        small = run_pypbd(
            mesh, fixed, material, steps=120, average=66, substeps=int(np.ceil(H * auto / 0.15))
        )
        print(
            f"| {n} | {mesh.n_tets} | {-fem[tip, 1].mean() / beam:.3f} | {sag(ref['mean']):.3f} | "
            f"{sag(same['mean']):.3f} | {sag(ours['final']):.3f} | {sag(small['mean']):.3f} |",
            flush=True,
        )


def main() -> None:
    """Parse the options and print the requested parts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", default="all", choices=["speed", "table", "deflection", "all"])
    parser.add_argument("--quick", action="store_true", help="smaller meshes only")
    args = parser.parse_args()
    print(f"numba kernels: {kernels.AVAILABLE}; cores: {os.cpu_count()}; load: {os.getloadavg()}")
    targets = [3000] if args.quick else [5000, 20000]
    if args.part in ("speed", "all"):
        speed(targets)
    if args.part in ("table", "all"):
        table([3000] if args.quick else [3000, 15000])
    if args.part in ("deflection", "all"):
        deflection([2, 3, 4] if args.quick else [4, 5, 6])


if __name__ == "__main__":
    main()
