"""numba kernels for the coloured Gauss-Seidel sweep (the same math as :mod:`pdeanim.sim.constraints`).

numba is optional: ``AVAILABLE`` is False when it cannot be imported and the solver then uses the numpy path.
Tets of one colour share no point, so a colour may run in parallel (``prange``) with a deterministic result.
"""

from __future__ import annotations

import numpy as np

from .constraints import ROTATION_ITERATIONS

try:
    import numba
    from numba import njit, prange

    AVAILABLE = True
except ImportError:  # pragma: no cover - numba is a pinned dependency; this keeps the numpy path usable
    AVAILABLE = False
    numba = None
    prange = range


def _deformation(x, t, dm_inv, k, f):  # pragma: no cover - compiled
    """f (3, 3) = Ds Dm^-1 of tet k with corners t (4,)."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += (x[t[m + 1], i] - x[t[0], i]) * dm_inv[k, m, j]
            f[i, j] = s


def _quat_matrix(q, r):  # pragma: no cover - compiled
    """r (3, 3) = rotation of unit quaternion q (w, x, y, z)."""
    w, a, b, c = q[0], q[1], q[2], q[3]
    r[0, 0], r[0, 1], r[0, 2] = 1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)
    r[1, 0], r[1, 1], r[1, 2] = 2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)
    r[2, 0], r[2, 1], r[2, 2] = 2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)


def _rotation(f, q, r, iterations):  # pragma: no cover - compiled
    """Refine q (4,) in place towards the rotation closest to f (Muller et al. 2016); r is scratch."""
    for _ in range(iterations):
        _quat_matrix(q, r)
        ox = oy = oz = 0.0
        dot = 0.0
        for i in range(3):
            ox += r[1, i] * f[2, i] - r[2, i] * f[1, i]
            oy += r[2, i] * f[0, i] - r[0, i] * f[2, i]
            oz += r[0, i] * f[1, i] - r[1, i] * f[0, i]
            dot += r[0, i] * f[0, i] + r[1, i] * f[1, i] + r[2, i] * f[2, i]
        inv = 1.0 / (abs(dot) + 1e-9)
        ox, oy, oz = ox * inv, oy * inv, oz * inv
        dw, dx, dy, dz = 1.0, 0.5 * ox, 0.5 * oy, 0.5 * oz
        w, a, b, c = q[0], q[1], q[2], q[3]
        nw = dw * w - (dx * a + dy * b + dz * c)
        na = dw * a + w * dx + (dy * c - dz * b)
        nb = dw * b + w * dy + (dz * a - dx * c)
        nc = dw * c + w * dz + (dx * b - dy * a)
        norm = np.sqrt(nw * nw + na * na + nb * nb + nc * nc)
        q[0], q[1], q[2], q[3] = nw / norm, na / norm, nb / norm, nc / norm


def _project(x, t, dm_inv, w, k, cval, dcdf, alpha, lam, g):  # pragma: no cover - compiled
    """Apply one XPBD update of a constraint with value cval and dC/dF dcdf to tet k; returns dlambda."""
    for i in range(3):
        g[0, i] = 0.0
    for a in range(3):
        for i in range(3):
            s = 0.0
            for m in range(3):
                s += dcdf[i, m] * dm_inv[k, a, m]
            g[a + 1, i] = s
            g[0, i] -= s
    denom = alpha
    for a in range(4):
        denom += w[k, a] * (g[a, 0] ** 2 + g[a, 1] ** 2 + g[a, 2] ** 2)
    if denom <= 0.0:
        return 0.0
    dlam = (-cval - alpha * lam) / denom
    for a in range(4):
        for i in range(3):
            x[t[a], i] += w[k, a] * g[a, i] * dlam
    return dlam


CHUNK = 256
"""Tets per parallel work item (scratch arrays are allocated once per chunk, not per tet)."""


def _solve_range(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,  # pragma: no cover
                 start, stop):
    """Deviatoric then volume XPBD update of tets start:stop (one colour: no shared points, any order)."""
    for chunk in prange((stop - start + CHUNK - 1) // CHUNK):
        f = np.empty((3, 3))
        r = np.empty((3, 3))
        d = np.empty((3, 3))
        g = np.empty((4, 3))
        for k in range(start + chunk * CHUNK, min(stop, start + (chunk + 1) * CHUNK)):
            _solve_tet(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters, k, f, r, d, g)


def _solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,  # pragma: no cover
                 offsets, parallel):
    """One Gauss-Seidel sweep: the colours in order, each colour's tets independently."""
    for c in range(offsets.shape[0] - 1):
        if parallel:
            _solve_range_parallel(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,
                                  offsets[c], offsets[c + 1])
        else:
            _solve_range_serial(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,
                                offsets[c], offsets[c + 1])


def _solve_tet(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,  # pragma: no cover
               k, f, r, d, g):
    """Deviatoric then volume update of tet k, with scratch arrays f, r, d (3, 3) and g (4, 3)."""
    t = tets[k]
    q = rot[k]
    _deformation(x, t, dm_inv, k, f)
    _rotation(f, q, r, rot_iters)
    _quat_matrix(q, r)
    c = 0.0
    for i in range(3):
        for j in range(3):
            d[i, j] = f[i, j] - r[i, j]
            c += d[i, j] * d[i, j]
    c = np.sqrt(c)
    inv = 1.0 / max(c, 1e-12)
    for i in range(3):
        for j in range(3):
            d[i, j] *= inv
    lam_d[k] += _project(x, t, dm_inv, w, k, c, d, alpha_d[k] * inv_dt2, lam_d[k], g)
    _deformation(x, t, dm_inv, k, f)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            d[i, j] = f[i1, j1] * f[i2, j2] - f[i1, j2] * f[i2, j1]
    c = f[0, 0] * d[0, 0] + f[0, 1] * d[0, 1] + f[0, 2] * d[0, 2] - 1.0
    lam_h[k] += _project(x, t, dm_inv, w, k, c, d, alpha_h[k] * inv_dt2, lam_h[k], g)


PARALLEL_MIN_TETS = 4096
"""Meshes with fewer tets run serially: a parallel launch per colour costs more than it saves (and stalls on
busy cores)."""

if AVAILABLE:
    _deformation = njit(inline="always", cache=True)(_deformation)
    _quat_matrix = njit(inline="always", cache=True)(_quat_matrix)
    _rotation = njit(inline="always", cache=True)(_rotation)
    _project = njit(inline="always", cache=True)(_project)
    _solve_tet = njit(inline="always", cache=True)(_solve_tet)
    _solve_range_serial = njit(cache=True)(_solve_range)
    _solve_range_parallel = njit(parallel=True, cache=True)(_solve_range)
    _solve_sweep = njit(cache=True)(_solve_sweep)
else:  # pragma: no cover
    _solve_sweep = None

_threads = 1


def set_threads(n: int) -> None:
    """Use up to n worker threads on large meshes (1, the default, keeps the solver single-threaded)."""
    global _threads
    if AVAILABLE:
        _threads = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
        numba.set_num_threads(_threads)


def solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, offsets) -> None:
    """One sweep over all colours in a single compiled call (serial or parallel: the same result)."""
    parallel = _threads > 1 and len(tets) >= PARALLEL_MIN_TETS
    _solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, ROTATION_ITERATIONS, offsets,
                 parallel)
