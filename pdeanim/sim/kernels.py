"""numba kernels for the coloured Gauss-Seidel sweep (the same math as :mod:`pdeanim.sim.constraints`).

numba is optional: ``AVAILABLE`` is False when it cannot be imported and the solver then uses the numpy path.
Tets of one colour share no point, so a colour is processed in chunks of ``CHUNK`` tets: the chunk's corners,
rotations and multipliers are gathered into a small struct-of-arrays buffer, one fused, branch-free pass does
both constraint updates per tet with the per-tet constants read from a precomputed chunked layout (it
vectorises: SIMD lanes are independent tets), and the buffer is scattered back. That is exactly the
sequential Gauss-Seidel result, bit for bit, in any chunk order. Large meshes are split into parts that share
no point (``parts``), solved one after the other or at the same time on threads (the kernels release the GIL;
see :mod:`pdeanim.sim.workers`) with the same result, followed by the tets between parts. 3 x 3 matrices are
9-tuples of scalars (row-major) that stay in registers;
no fastmath, so the arithmetic is the scalar IEEE one in the same order as the one-tet-at-a-time loop.
"""

from __future__ import annotations

import os
from functools import partial

import numpy as np

from .constraints import ROTATION_ITERATIONS
from .workers import JobPool

try:
    from numba import njit

    AVAILABLE = True
except ImportError:  # pragma: no cover - numba is a pinned dependency; this keeps the numpy path usable
    AVAILABLE = False

CHUNK = 128
"""Tets per chunk: a gather buffer of ROWS x STRIDE float64 (19 KiB) stays in the L1 cache."""

LANES = 8
"""Chunks are padded to a multiple of this many tets (AVX-512 float64 lanes) so no scalar remainder loop runs;
the padding lanes hold a zero tet with zero constants (see :func:`pack_constants`)."""

STRIDE = CHUNK + 8
"""Buffer row stride in float64: rows 1088 bytes apart do not pile onto the same L1 cache sets."""

ROWS = 18
"""Gather-buffer rows per tet: corners (12), quaternion (4), lambda_d and lambda_h."""

N_CONST = 15
"""Rows of the per-tet constants (see :func:`pack_constants`): Dm^-1 (9), inverse masses (4), alpha_d,
alpha_h."""


def chunk_slots(offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M,) int64 slot of each tet in the chunked layout, (C + 1,) int64 first chunk of each colour).

    Each colour (offsets (C + 1,)) is cut into chunks of CHUNK consecutive tets; tet k of a chunk starting at
    tet s sits in lane k - s.
    """
    sizes = np.diff(offsets)
    first = np.concatenate([[0], np.cumsum(-(-sizes // CHUNK))]).astype(np.int64)
    local = np.arange(offsets[-1]) - np.repeat(offsets[:-1], sizes)
    chunk = np.repeat(first[:-1], sizes) + local // CHUNK
    return chunk * STRIDE * N_CONST + local % CHUNK, first


def pack_constants(dm_inv: np.ndarray, w: np.ndarray, alpha_d: np.ndarray, alpha_h: np.ndarray,
                   offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-tet constants in the kernels' chunked layout: ((chunks * N_CONST * STRIDE,) f64, (C + 1,) i64
    chunks).

    Rows per chunk: Dm^-1 row-major (9), corner inverse masses w0..w3 (4), alpha_d, alpha_h; tets in colour
    order (offsets (C + 1,)); the second array is each colour's first chunk (see :func:`chunk_slots`).
    """
    m = len(dm_inv)
    rows = np.concatenate(
        [np.reshape(dm_inv, (m, 9)), np.reshape(w, (m, 4)), alpha_d[:, None], alpha_h[:, None]], axis=1
    )
    slots, first = chunk_slots(np.asarray(offsets, np.int64))
    out = np.zeros(int(first[-1]) * N_CONST * STRIDE)
    out[slots[:, None] + STRIDE * np.arange(N_CONST)] = rows
    return out, first


def _deformation(p, m):  # pragma: no cover - compiled
    """F = Ds Dm^-1 (9-tuple) of the corners p (12-tuple) and the rest inverse m (9-tuple)."""
    e1x, e1y, e1z = p[3] - p[0], p[4] - p[1], p[5] - p[2]
    e2x, e2y, e2z = p[6] - p[0], p[7] - p[1], p[8] - p[2]
    e3x, e3y, e3z = p[9] - p[0], p[10] - p[1], p[11] - p[2]
    return (e1x * m[0] + e2x * m[3] + e3x * m[6], e1x * m[1] + e2x * m[4] + e3x * m[7],
            e1x * m[2] + e2x * m[5] + e3x * m[8],
            e1y * m[0] + e2y * m[3] + e3y * m[6], e1y * m[1] + e2y * m[4] + e3y * m[7],
            e1y * m[2] + e2y * m[5] + e3y * m[8],
            e1z * m[0] + e2z * m[3] + e3z * m[6], e1z * m[1] + e2z * m[4] + e3z * m[7],
            e1z * m[2] + e2z * m[5] + e3z * m[8])


def _quat_matrix(w, a, b, c):  # pragma: no cover - compiled
    """Rotation matrix (9-tuple) of the unit quaternion (w, a, b, c)."""
    return (1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b),
            2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a),
            2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b))


def _rotation(f, w, a, b, c):  # pragma: no cover - compiled
    """Refine the quaternion (w, a, b, c) towards the rotation closest to f (Muller et al. 2016)."""
    for _ in range(ROTATION_ITERATIONS):  # a compile-time constant: unrolled
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
        # (1, omega / 2) times q, as in constraints.extract_rotation
        dx, dy, dz = ox * inv, oy * inv, oz * inv
        nw = w - (dx * a + dy * b + dz * c)
        na = a + w * dx + (dy * c - dz * b)
        nb = b + w * dy + (dz * a - dx * c)
        nc = c + w * dz + (dx * b - dy * a)
        norm = np.sqrt(nw * nw + na * na + nb * nb + nc * nc)
        w, a, b, c = nw / norm, na / norm, nb / norm, nc / norm
    return w, a, b, c


def _project(p, m, wk, cval, d, alpha, lam):  # pragma: no cover - compiled
    """One XPBD update of a constraint with value cval and dC/dF d (9-tuple): (new corners, dlambda)."""
    g1x = d[0] * m[0] + d[1] * m[1] + d[2] * m[2]
    g1y = d[3] * m[0] + d[4] * m[1] + d[5] * m[2]
    g1z = d[6] * m[0] + d[7] * m[1] + d[8] * m[2]
    g2x = d[0] * m[3] + d[1] * m[4] + d[2] * m[5]
    g2y = d[3] * m[3] + d[4] * m[4] + d[5] * m[5]
    g2z = d[6] * m[3] + d[7] * m[4] + d[8] * m[5]
    g3x = d[0] * m[6] + d[1] * m[7] + d[2] * m[8]
    g3y = d[3] * m[6] + d[4] * m[7] + d[5] * m[8]
    g3z = d[6] * m[6] + d[7] * m[7] + d[8] * m[8]
    g0x, g0y, g0z = -(g1x + g2x + g3x), -(g1y + g2y + g3y), -(g1z + g2z + g3z)
    w0, w1, w2, w3 = wk
    denom = alpha + w0 * (g0x * g0x + g0y * g0y + g0z * g0z) + w1 * (g1x * g1x + g1y * g1y + g1z * g1z) \
        + w2 * (g2x * g2x + g2y * g2y + g2z * g2z) + w3 * (g3x * g3x + g3y * g3y + g3z * g3z)
    dlam = (-cval - alpha * lam) / denom if denom > 0.0 else 0.0  # a select, not a branch
    s0, s1, s2, s3 = w0 * dlam, w1 * dlam, w2 * dlam, w3 * dlam
    return (
        p[0] + s0 * g0x,
        p[1] + s0 * g0y,
        p[2] + s0 * g0z,
        p[3] + s1 * g1x,
        p[4] + s1 * g1y,
        p[5] + s1 * g1z,
        p[6] + s2 * g2x,
        p[7] + s2 * g2y,
        p[8] + s2 * g2z,
        p[9] + s3 * g3x,
        p[10] + s3 * g3y,
        p[11] + s3 * g3z,
    ), dlam


def _deviatoric(p, q, m, wk, alpha, lam):  # pragma: no cover - compiled
    """C_D = |F - R|_F update: (new corners, refined quaternion, dlambda)."""
    f = _deformation(p, m)
    qw, qa, qb, qc = _rotation(f, q[0], q[1], q[2], q[3])
    r = _quat_matrix(qw, qa, qb, qc)
    d0, d1, d2 = f[0] - r[0], f[1] - r[1], f[2] - r[2]
    d3, d4, d5 = f[3] - r[3], f[4] - r[4], f[5] - r[5]
    d6, d7, d8 = f[6] - r[6], f[7] - r[7], f[8] - r[8]
    c = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3 + d4 * d4 + d5 * d5 + d6 * d6 + d7 * d7 + d8 * d8)
    s = 1.0 / max(c, 1e-12)
    d = (d0 * s, d1 * s, d2 * s, d3 * s, d4 * s, d5 * s, d6 * s, d7 * s, d8 * s)
    p, dlam = _project(p, m, wk, c, d, alpha, lam)
    return p, (qw, qa, qb, qc), dlam


def _volume(p, m, wk, alpha, lam):  # pragma: no cover - compiled
    """C_H = det F - 1 update: (new corners, dlambda)."""
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = _deformation(p, m)
    cof = (f11 * f22 - f12 * f21, f12 * f20 - f10 * f22, f10 * f21 - f11 * f20,
           f21 * f02 - f22 * f01, f22 * f00 - f20 * f02, f20 * f01 - f21 * f00,
           f01 * f12 - f02 * f11, f02 * f10 - f00 * f12, f00 * f11 - f01 * f10)
    c = f00 * cof[0] + f01 * cof[1] + f02 * cof[2] - 1.0
    return _project(p, m, wk, c, cof, alpha, lam)


def _solve_chunk(b, cst, n, inv_dt2):  # pragma: no cover - compiled
    """Deviatoric then volume update of the n tets in the chunk buffer b (ROWS * STRIDE,), in place.

    cst (N_CONST * STRIDE,) holds the chunk's constants. Flat arrays with compile-time row offsets:
    the rows provably never overlap, so the loop vectorises (SIMD lanes are independent tets).
    """
    for j in range(n):
        p = (b[j], b[STRIDE + j], b[2 * STRIDE + j], b[3 * STRIDE + j], b[4 * STRIDE + j], b[5 * STRIDE + j],
             b[6 * STRIDE + j], b[7 * STRIDE + j], b[8 * STRIDE + j], b[9 * STRIDE + j], b[10 * STRIDE + j],
             b[11 * STRIDE + j])
        q = (b[12 * STRIDE + j], b[13 * STRIDE + j], b[14 * STRIDE + j], b[15 * STRIDE + j])
        m = (cst[j], cst[j + STRIDE], cst[j + 2 * STRIDE], cst[j + 3 * STRIDE], cst[j + 4 * STRIDE],
             cst[j + 5 * STRIDE], cst[j + 6 * STRIDE], cst[j + 7 * STRIDE], cst[j + 8 * STRIDE])
        wk = (cst[j + 9 * STRIDE], cst[j + 10 * STRIDE], cst[j + 11 * STRIDE], cst[j + 12 * STRIDE])
        p, q, dlam_d = _deviatoric(p, q, m, wk, cst[j + 13 * STRIDE] * inv_dt2, b[16 * STRIDE + j])
        p, dlam_h = _volume(p, m, wk, cst[j + 14 * STRIDE] * inv_dt2, b[17 * STRIDE + j])
        b[16 * STRIDE + j] += dlam_d
        b[17 * STRIDE + j] += dlam_h
        b[j], b[STRIDE + j], b[2 * STRIDE + j], b[3 * STRIDE + j] = p[0], p[1], p[2], p[3]
        b[4 * STRIDE + j], b[5 * STRIDE + j], b[6 * STRIDE + j], b[7 * STRIDE + j] = p[4], p[5], p[6], p[7]
        b[8 * STRIDE + j], b[9 * STRIDE + j], b[10 * STRIDE + j], b[11 * STRIDE + j] = (
            p[8],
            p[9],
            p[10],
            p[11],
        )
        b[12 * STRIDE + j], b[13 * STRIDE + j], b[14 * STRIDE + j], b[15 * STRIDE + j] = (
            q[0],
            q[1],
            q[2],
            q[3],
        )


def _chunk(x, rot_in, rot, tets, cst, lam, inv_dt2, b, chunk, base, n):  # pragma: no cover - compiled
    """Gather tets base:base+n (chunk number ``chunk`` of one colour) into b, update them, scatter them back.

    Rotations are read from rot_in and written to rot; lam (2, M) or (2, 0) for multipliers that start at 0.
    """
    keep = lam.shape[1] > 0
    for j in range(n):
        k = base + j
        for c in range(4):
            i = tets[k, c]
            b[3 * c * STRIDE + j], b[(3 * c + 1) * STRIDE + j], b[(3 * c + 2) * STRIDE + j] = (
                x[i, 0],
                x[i, 1],
                x[i, 2],
            )
            b[(12 + c) * STRIDE + j] = rot_in[k, c]
        b[16 * STRIDE + j] = lam[0, k] if keep else 0.0
        b[17 * STRIDE + j] = lam[1, k] if keep else 0.0
    padded = -(-n // LANES) * LANES
    for j in range(n, padded):  # idle SIMD lanes: a zero tet with no mass moves nothing and stays finite
        for r in range(ROWS):
            b[r * STRIDE + j] = 0.0
        b[12 * STRIDE + j] = 1.0
    cb = chunk * (N_CONST * STRIDE)
    # a view: indices provably >= 0, no gathers
    _solve_chunk(b, cst[cb:cb + N_CONST * STRIDE], padded, inv_dt2)
    for j in range(n):
        k = base + j
        for c in range(4):
            i = tets[k, c]
            x[i, 0], x[i, 1], x[i, 2] = (
                b[3 * c * STRIDE + j],
                b[(3 * c + 1) * STRIDE + j],
                b[(3 * c + 2) * STRIDE + j],
            )
            rot[k, c] = b[(12 + c) * STRIDE + j]
        if keep:
            lam[0, k], lam[1, k] = b[16 * STRIDE + j], b[17 * STRIDE + j]


def _colours(x, rot_in, rot, tets, cst, lam, inv_dt2, offsets, chunks, first, last, buf):  # pragma: no cover
    """Colours first:last in order, each colour's tets in independent chunks."""
    for c in range(first, last):
        chunk = chunks[c]
        for base in range(offsets[c], offsets[c + 1], CHUNK):
            _chunk(
                x, rot_in, rot, tets, cst, lam, inv_dt2, buf, chunk, base, min(CHUNK, offsets[c + 1] - base)
            )
            chunk += 1


def _solve_sweep(x, rot_in, rot, tets, cst, lam, inv_dt2, offsets, chunks):  # pragma: no cover - compiled
    """One serial Gauss-Seidel sweep: all colours in order (the parts' colours part after part, then the
    rest)."""
    buf = np.empty(ROWS * STRIDE)
    _colours(x, rot_in, rot, tets, cst, lam, inv_dt2, offsets, chunks, 0, offsets.shape[0] - 1, buf)


def _predict(x_in, v_in, inv_mass, damp, dv, dt, x):  # pragma: no cover - compiled
    """x = x_in + dt (damp v_in + dv) for free points (inverse mass > 0), x_in + dt damp v_in for pinned
    ones."""
    for i in range(x.shape[0]):
        free = inv_mass[i] > 0
        for c in range(3):
            x[i, c] = x_in[i, c] + dt * (v_in[i, c] * damp + (dv[c] if free else 0.0))


def _ground(x, x_prev, point, n, friction):  # pragma: no cover - compiled
    """Points behind the plane (point, unit normal n) onto it; friction in [0, 1] removes that part of the
    sliding since x_prev (the same maths as ``xpbd.project_ground``'s numpy path)."""
    for i in range(x.shape[0]):
        depth = (x[i, 0] - point[0]) * n[0] + (x[i, 1] - point[1]) * n[1] + (x[i, 2] - point[2]) * n[2]
        if depth < 0:
            for c in range(3):
                x[i, c] -= depth * n[c]
            if friction > 0:
                d0, d1, d2 = x[i, 0] - x_prev[i, 0], x[i, 1] - x_prev[i, 1], x[i, 2] - x_prev[i, 2]
                dn = d0 * n[0] + d1 * n[1] + d2 * n[2]
                x[i, 0] -= friction * (d0 - dn * n[0])
                x[i, 1] -= friction * (d1 - dn * n[1])
                x[i, 2] -= friction * (d2 - dn * n[2])


PARALLEL_MIN_TETS = 4096
"""Meshes with fewer tets are not split into independent parts (see ``xpbd.PARTS``) and always run
serially."""

if AVAILABLE:
    _opts = {"cache": True, "error_model": "numpy", "boundscheck": False}
    for _name in ("_deformation", "_quat_matrix", "_rotation", "_project", "_deviatoric", "_volume"):
        globals()[_name] = njit(inline="always", **_opts)(globals()[_name])
    _solve_chunk = njit(**_opts)(_solve_chunk)
    _chunk = njit(inline="always", **_opts)(_chunk)
    _colours = njit(nogil=True, **_opts)(_colours)
    _solve_sweep = njit(**_opts)(_solve_sweep)
    _predict = njit(**_opts)(_predict)
    _ground = njit(**_opts)(_ground)
else:  # pragma: no cover
    _solve_sweep = _predict = _ground = None

_threads = 1
_pool: JobPool | None = None


def set_threads(n: int) -> None:
    """Use up to n threads on meshes split into parts (1, the default, keeps the solver single-threaded)."""
    global _threads, _pool
    _threads = max(1, min(int(n), os.cpu_count() or 1))
    if AVAILABLE and _threads > 1 and (_pool is None or _pool.size < _threads):
        _pool = JobPool(_threads - 1)


def solve_sweep(
    x: np.ndarray,
    rot_in: np.ndarray,
    rot: np.ndarray,
    tets: np.ndarray,
    cst: np.ndarray,
    lam: np.ndarray,
    inv_dt2: float,
    offsets: np.ndarray,
    chunks: np.ndarray,
    parts: np.ndarray,
) -> None:
    """One sweep over all colours (serial, or the parts on several threads: the same result).

    x (N, 3) f64 is updated in place; rotation guesses are read from rot_in (M, 4) f64 and written to rot (M,
    4)
    (the same array or not); tets (M, 4) int64 in colour order; cst and chunks from :func:`pack_constants`
    with
    the same colour offsets (C + 1,) int64; parts (P + 1,) int64 colour bounds of groups sharing no point (the
    colours after parts[-1] run serially); lam (2, M) f64 multipliers accumulated in this step, or (2, 0) when
    they start at 0 and are not needed afterwards (a single sweep per step).
    """
    if _threads == 1 or len(parts) < 3 or _pool is None:
        _solve_sweep(x, rot_in, rot, tets, cst, lam, inv_dt2, offsets, chunks)
        return
    args = (x, rot_in, rot, tets, cst, lam, inv_dt2, offsets, chunks)
    _pool.run([partial(_colours, *args, parts[p], parts[p + 1], np.empty(ROWS * STRIDE))
               for p in range(len(parts) - 1)])
    _colours(*args, parts[-1], len(offsets) - 1, np.empty(ROWS * STRIDE))


def predict(x_in: np.ndarray, v_in: np.ndarray, inv_mass: np.ndarray, damp: float, dv: np.ndarray, dt: float,
            x: np.ndarray) -> None:
    """Explicit prediction of a substep into x (N, 3): damped velocity plus dv (3,) (gravity dt) on free
    points."""
    _predict(x_in, v_in, inv_mass, damp, dv, dt, x)


def ground(x: np.ndarray, x_prev: np.ndarray, point: np.ndarray, normal: np.ndarray, friction: float) -> None:
    """Project x (N, 3) onto the allowed side of the plane (point (3,), unit normal (3,)), friction in [0,
    1]."""
    _ground(x, x_prev, point, normal, friction)
