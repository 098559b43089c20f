"""Run one pypbd (PositionBasedDynamics 2.2.2) simulation in this process: the reference engine of the
benchmarks.

pypbd is a process-wide singleton, so every case runs in its own child process:
``python benchmarks/sim_pypbd.py IN.npz OUT.npz`` with points, tets, masses (0 = pinned), steps, substeps,
iterations, h and young/poisson in IN. Gravity is pypbd's fixed -9.81 y. Writes final positions, the mean
positions over the last ``average`` steps, and the seconds spent stepping. Needs .venv-bench (pypbd
installed).
"""

from __future__ import annotations

import sys
import time

import numpy as np


def main(src: str, dst: str) -> None:
    """Build the tet model with FEM-based PBD constraints (pypbd's default solid method 2) and step it."""
    import pypbd as pbd

    data = dict(np.load(src))
    sim = pbd.Simulation.getCurrent()
    sim.initDefault()
    model = sim.getModel()
    tet = model.addTetModel(list(data["points"]), data["tets"].ravel().tolist())
    particles = model.getParticles()
    for i, m in enumerate(data["masses"]):
        particles.setMass(i, float(m))
    young, poisson = float(data["young"]), float(data["poisson"])
    model.addSolidConstraints(tet, 2, young, poisson, young, False, False)
    step = sim.getTimeStep()
    step.setValueUInt(pbd.TimeStepController.NUM_SUB_STEPS, int(data["substeps"]))
    step.setValueUInt(pbd.TimeStepController.MAX_ITERATIONS, int(data["iterations"]))
    pbd.TimeManager.getCurrent().setTimeStepSize(float(data["h"]))
    steps, average = int(data["steps"]), int(data["average"])
    n = particles.size()
    mean = np.zeros((n, 3))
    seconds = 0.0
    for s in range(steps):
        started = time.perf_counter()
        step.step(model)
        seconds += time.perf_counter() - started
        if s >= steps - average:
            mean += np.array([particles.getPosition(i) for i in range(n)])
    final = np.array([particles.getPosition(i) for i in range(n)])
    np.savez(dst, final=final, mean=mean / max(average, 1), seconds=seconds)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
