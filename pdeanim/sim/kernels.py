"""numba kernels for the coloured Gauss-Seidel sweep (the same math as :mod:`pdeanim.sim.constraints`).

numba is optional: ``AVAILABLE`` is False when it cannot be imported and the solver then uses the numpy path.
Tets of one colour share no point, so a colour may run in parallel (``prange``) with a deterministic result.
3 x 3 matrices are passed around as 9-tuples of scalars (row-major) so that they stay in registers.
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


def _deformation(x, a, b, c, d, m):  # pragma: no cover - compiled
    """F = Ds Dm^-1 (9-tuple) for corners a, b, c, d and the rest inverse m (3, 3)."""
    e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
    e2x, e2y, e2z = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
    e3x, e3y, e3z = x[d, 0] - x[a, 0], x[d, 1] - x[a, 1], x[d, 2] - x[a, 2]
    m00, m01, m02 = m[0, 0], m[0, 1], m[0, 2]
    m10, m11, m12 = m[1, 0], m[1, 1], m[1, 2]
    m20, m21, m22 = m[2, 0], m[2, 1], m[2, 2]
    return (e1x * m00 + e2x * m10 + e3x * m20, e1x * m01 + e2x * m11 + e3x * m21, e1x * m02 + e2x * m12 + e3x * m22,
            e1y * m00 + e2y * m10 + e3y * m20, e1y * m01 + e2y * m11 + e3y * m21, e1y * m02 + e2y * m12 + e3y * m22,
            e1z * m00 + e2z * m10 + e3z * m20, e1z * m01 + e2z * m11 + e3z * m21, e1z * m02 + e2z * m12 + e3z * m22)


def _quat_matrix(w, a, b, c):  # pragma: no cover - compiled
    """Rotation matrix (9-tuple) of the unit quaternion (w, a, b, c)."""
    return (1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b),
            2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a),
            2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b))


def _rotation(f, q, iterations):  # pragma: no cover - compiled
    """Refine q (4,) in place towards the rotation closest to f (Muller et al. 2016); returns its matrix."""
    w, a, b, c = q[0], q[1], q[2], q[3]
    for _ in range(iterations):
        r = _quat_matrix(w, a, b, c)
        ox = oy = oz = dot = 0.0
        for i in range(3):  # sum over columns i of r_i x f_i
            r0, r1, r2 = r[i], r[3 + i], r[6 + i]
            f0, f1, f2 = f[i], f[3 + i], f[6 + i]
            ox += r1 * f2 - r2 * f1
            oy += r2 * f0 - r0 * f2
            oz += r0 * f1 - r1 * f0
            dot += r0 * f0 + r1 * f1 + r2 * f2
        inv = 0.5 / (abs(dot) + 1e-9)
        dx, dy, dz = ox * inv, oy * inv, oz * inv  # (1, omega / 2) times q, as in constraints.extract_rotation
        nw = w - (dx * a + dy * b + dz * c)
        na = a + w * dx + (dy * c - dz * b)
        nb = b + w * dy + (dz * a - dx * c)
        nc = c + w * dz + (dx * b - dy * a)
        norm = np.sqrt(nw * nw + na * na + nb * nb + nc * nc)
        w, a, b, c = nw / norm, na / norm, nb / norm, nc / norm
    q[0], q[1], q[2], q[3] = w, a, b, c
    return _quat_matrix(w, a, b, c)


def _project(x, i0, i1, i2, i3, m, wk, cval, p, alpha, lam):  # pragma: no cover - compiled
    """One XPBD update of a constraint with value cval and dC/dF p (9-tuple); returns dlambda."""
    g1x = p[0] * m[0, 0] + p[1] * m[0, 1] + p[2] * m[0, 2]
    g1y = p[3] * m[0, 0] + p[4] * m[0, 1] + p[5] * m[0, 2]
    g1z = p[6] * m[0, 0] + p[7] * m[0, 1] + p[8] * m[0, 2]
    g2x = p[0] * m[1, 0] + p[1] * m[1, 1] + p[2] * m[1, 2]
    g2y = p[3] * m[1, 0] + p[4] * m[1, 1] + p[5] * m[1, 2]
    g2z = p[6] * m[1, 0] + p[7] * m[1, 1] + p[8] * m[1, 2]
    g3x = p[0] * m[2, 0] + p[1] * m[2, 1] + p[2] * m[2, 2]
    g3y = p[3] * m[2, 0] + p[4] * m[2, 1] + p[5] * m[2, 2]
    g3z = p[6] * m[2, 0] + p[7] * m[2, 1] + p[8] * m[2, 2]
    g0x, g0y, g0z = -(g1x + g2x + g3x), -(g1y + g2y + g3y), -(g1z + g2z + g3z)
    w0, w1, w2, w3 = wk[0], wk[1], wk[2], wk[3]
    denom = alpha + w0 * (g0x * g0x + g0y * g0y + g0z * g0z) + w1 * (g1x * g1x + g1y * g1y + g1z * g1z) \
        + w2 * (g2x * g2x + g2y * g2y + g2z * g2z) + w3 * (g3x * g3x + g3y * g3y + g3z * g3z)
    if denom <= 0.0:
        return 0.0
    dlam = (-cval - alpha * lam) / denom
    s0, s1, s2, s3 = w0 * dlam, w1 * dlam, w2 * dlam, w3 * dlam
    x[i0, 0] += s0 * g0x
    x[i0, 1] += s0 * g0y
    x[i0, 2] += s0 * g0z
    x[i1, 0] += s1 * g1x
    x[i1, 1] += s1 * g1y
    x[i1, 2] += s1 * g1z
    x[i2, 0] += s2 * g2x
    x[i2, 1] += s2 * g2y
    x[i2, 2] += s2 * g2z
    x[i3, 0] += s3 * g3x
    x[i3, 1] += s3 * g3y
    x[i3, 2] += s3 * g3z
    return dlam


def _solve_tet(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters, k):  # pragma: no cover
    """Deviatoric (|F - R|) then volume (det F - 1) update of tet k."""
    i0, i1, i2, i3 = tets[k, 0], tets[k, 1], tets[k, 2], tets[k, 3]
    m = dm_inv[k]
    wk = w[k]
    f = _deformation(x, i0, i1, i2, i3, m)
    r = _rotation(f, rot[k], rot_iters)
    d0, d1, d2 = f[0] - r[0], f[1] - r[1], f[2] - r[2]
    d3, d4, d5 = f[3] - r[3], f[4] - r[4], f[5] - r[5]
    d6, d7, d8 = f[6] - r[6], f[7] - r[7], f[8] - r[8]
    c = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3 + d4 * d4 + d5 * d5 + d6 * d6 + d7 * d7 + d8 * d8)
    s = 1.0 / max(c, 1e-12)
    p = (d0 * s, d1 * s, d2 * s, d3 * s, d4 * s, d5 * s, d6 * s, d7 * s, d8 * s)
    lam_d[k] += _project(x, i0, i1, i2, i3, m, wk, c, p, alpha_d[k] * inv_dt2, lam_d[k])
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = _deformation(x, i0, i1, i2, i3, m)
    cof = (f11 * f22 - f12 * f21, f12 * f20 - f10 * f22, f10 * f21 - f11 * f20,
           f21 * f02 - f22 * f01, f22 * f00 - f20 * f02, f20 * f01 - f21 * f00,
           f01 * f12 - f02 * f11, f02 * f10 - f00 * f12, f00 * f11 - f01 * f10)
    c = f00 * cof[0] + f01 * cof[1] + f02 * cof[2] - 1.0
    lam_h[k] += _project(x, i0, i1, i2, i3, m, wk, c, cof, alpha_h[k] * inv_dt2, lam_h[k])


def _solve_range(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,  # pragma: no cover
                 start, stop):
    """Both updates for tets start:stop (one colour: no shared points, so any order or in parallel)."""
    for k in prange(start, stop):
        _solve_tet(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters, k)


def _solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,  # pragma: no cover
                 offsets, parallel):
    """One Gauss-Seidel sweep: the colours in order, each colour's tets independently."""
    for c in range(offsets.shape[0] - 1):
        if parallel:
            _solve_range_parallel(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters,
                                  offsets[c], offsets[c + 1])
        else:
            for k in range(offsets[c], offsets[c + 1]):
                _solve_tet(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, rot_iters, k)


PARALLEL_MIN_TETS = 4096
"""Meshes with fewer tets run serially: a parallel launch per colour costs more than it saves (and stalls on
busy cores)."""

if AVAILABLE:
    _deformation = njit(inline="always", cache=True)(_deformation)
    _quat_matrix = njit(inline="always", cache=True)(_quat_matrix)
    _rotation = njit(inline="always", cache=True)(_rotation)
    _project = njit(inline="always", cache=True)(_project)
    _solve_tet = njit(inline="always", cache=True)(_solve_tet)
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
        if _threads > 1:  # the serial path never starts numba's thread pool
            numba.set_num_threads(_threads)


def solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, offsets) -> None:
    """One sweep over all colours in a single compiled call (serial or parallel: the same result)."""
    parallel = _threads > 1 and len(tets) >= PARALLEL_MIN_TETS
    _solve_sweep(x, rot, tets, dm_inv, w, alpha_d, alpha_h, lam_d, lam_h, inv_dt2, ROTATION_ITERATIONS, offsets,
                 parallel)
