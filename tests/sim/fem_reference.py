"""Static linear-elastic FEM on linear tets (assembled with numpy, solved with scipy): the test's
reference."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pdeanim.sim.tetmesh import TetMesh


def element_stiffness(points: np.ndarray, tets: np.ndarray, young: float, poisson: float) -> np.ndarray:
    """(M, 12, 12) linear tet stiffness matrices (constant strain), dofs ordered corner-major."""
    p = points[tets]
    dm = (p[:, 1:] - p[:, :1]).transpose(0, 2, 1)
    dm_inv = np.linalg.inv(dm)
    vol = np.abs(np.linalg.det(dm)) / 6.0
    grads = np.concatenate([-dm_inv.sum(axis=1, keepdims=True), dm_inv], axis=1)  # (M, 4, 3) dN_a/dx
    m = len(tets)
    b = np.zeros((m, 6, 12))
    for a in range(4):
        gx, gy, gz = grads[:, a, 0], grads[:, a, 1], grads[:, a, 2]
        b[:, 0, 3 * a], b[:, 1, 3 * a + 1], b[:, 2, 3 * a + 2] = gx, gy, gz
        b[:, 3, 3 * a], b[:, 3, 3 * a + 1] = gy, gx
        b[:, 4, 3 * a + 1], b[:, 4, 3 * a + 2] = gz, gy
        b[:, 5, 3 * a], b[:, 5, 3 * a + 2] = gz, gx
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = young / (2 * (1 + poisson))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] += 2 * mu
    d[np.arange(3, 6), np.arange(3, 6)] = mu
    return np.einsum("mia,ij,mjb,m->mab", b, d, b, vol)


def static_displacement(
    mesh: TetMesh, young: float, poisson: float, density: float, gravity, fixed
) -> np.ndarray:
    """(N, 3) small-strain static displacement under gravity with ``fixed`` points clamped."""
    ke = element_stiffness(mesh.points, mesh.tets, young, poisson)
    dofs = (3 * mesh.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * mesh.n_points
    k = sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n, n))
    mass = np.bincount(mesh.tets.ravel(), np.repeat(density * mesh.volumes() / 4, 4), minlength=mesh.n_points)
    f = (mass[:, None] * np.asarray(gravity, float)).ravel()
    free = np.ones(n, bool)
    free[(3 * np.asarray(fixed)[:, None] + np.arange(3)).ravel()] = False
    u = np.zeros(n)
    u[free] = spla.spsolve(k[free][:, free].tocsc(), f[free])
    return u.reshape(-1, 3)
