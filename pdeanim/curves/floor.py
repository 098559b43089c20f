"""The spatial floor of a curve set: the error left when every frame is fitted on its own by each curve's
4-function space basis (the model's families), so no number of time segments can go below it.

Three motion variants are measured, as the fit can use them:

* ``absolute``: the positions themselves;
* ``displacement``: positions minus the first frame;
* ``rigid``: the residual after each curve's best rigid motion (Kabsch) from the first frame.

For every curve and coordinate the best (space kind, D) of a grid is chosen over all frames together (D is
constant within a fitted time segment). Vectorised over curves, points and frames; chunked over curves.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..curveset import CurveSet
from ..errors import ParameterError
from ..model.families import SPACE_KINDS, space_basis

MOTIONS = ("absolute", "displacement", "rigid")
D_GRID = (0.0, 2.0, 4.0, 6.0, 9.0)
CHUNK_VALUES = 4_000_000  # curves per chunk are chosen so a chunk holds about this many floats


@dataclass
class FloorReport:
    """Floor of one curve set and motion variant; errors are Euclidean per vertex and frame.

    per_curve_rms, per_curve_max : (C,) float64 absolute; rel_* are divided by ``diag`` (first-frame bbox).
    """

    motion: str
    rms: float
    max: float
    rel_rms: float
    rel_max: float
    diag: float
    per_curve_rms: np.ndarray = field(repr=False)
    per_curve_max: np.ndarray = field(repr=False)


def chord_parameters(rest: np.ndarray, idx: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(C, N) float64 chord-length parameter in [0, 1] on the rest positions (V, 3); padding gets 1."""
    p = rest[idx]
    step = np.linalg.norm(np.diff(p, axis=1), axis=2) * mask[:, 1:]
    cum = np.concatenate([np.zeros((len(idx), 1)), np.cumsum(step, axis=1)], axis=1)
    total = cum[:, -1:]
    n = mask.sum(axis=1, keepdims=True)
    even = np.minimum(np.arange(idx.shape[1])[None, :], n - 1) / np.maximum(n - 1, 1)
    u = np.where(total > 0, cum / np.where(total > 0, total, 1.0), even)
    return np.where(mask, u, 1.0)


def rigid_motions(rest: np.ndarray, frames: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid motion (Kabsch, no reflection) of every curve from rest to every frame.

    rest : (C, N, 3); frames : (F, C, N, 3); mask : (C, N) bool (padding ignored).
    Returns rot (F, C, 3, 3) and shift (F, C, 3) float64 with frame ~= rest @ rot + shift per curve.
    """
    w = mask[..., None].astype(np.float64)
    n = np.maximum(w.sum(axis=1), 1.0)  # (C, 1)
    pc = (rest * w).sum(axis=1) / n
    qc = (frames * w).sum(axis=2) / n
    p = (rest - pc[:, None]) * w
    q = (frames - qc[:, :, None]) * w
    h = np.einsum("cni,fcnj->fcij", p, q)
    u, _, vt = np.linalg.svd(h)
    det = np.sign(np.linalg.det(np.einsum("fcij,fcjk->fcik", u, vt)))
    det = np.where(det == 0, 1.0, det)
    vt = vt.copy()
    vt[..., 2, :] *= det[..., None]
    rot = np.einsum("fcij,fcjk->fcik", u, vt)  # p @ rot maps rest onto the frame
    return rot, qc - np.einsum("ci,fcij->fcj", pc, rot)


def kabsch_residual(rest: np.ndarray, frames: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Residual of each curve after its best rigid motion from the rest curve.

    rest : (C, N, 3); frames : (F, C, N, 3); mask : (C, N) bool. Returns (F, C, N, 3) float64.
    """
    rot, shift = rigid_motions(rest, frames, mask)
    fitted = np.einsum("cni,fcij->fcnj", rest, rot) + shift[:, :, None]
    return (frames - fitted) * mask[None, ..., None]


def motion_targets(frames: np.ndarray, idx: np.ndarray, mask: np.ndarray, motion: str) -> np.ndarray:
    """(F, C, N, 3) float64 values the space basis must fit for the motion variant."""
    x = frames[:, idx].astype(np.float64)
    if motion == "absolute":
        return x
    if motion == "displacement":
        return x - x[:1]
    return kabsch_residual(x[0], x, mask)


def _space_bases(u: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """Orthonormal column bases (C, N, 4) of every grid entry (rank-deficient directions zeroed)."""
    out = []
    for kind in SPACE_KINDS:
        for d in D_GRID:
            if kind == SPACE_KINDS[1] and d == 0.0:
                continue  # both kinds are the cubics at D = 0
            b = space_basis(u, np.full(len(u), d), kind) * mask[..., None]
            q, s, _ = np.linalg.svd(b, full_matrices=False)
            keep = s > 1e-10 * np.maximum(s[:, :1], 1e-300)
            out.append(q * keep[:, None, :])
    return out


def chunk_residual(y: np.ndarray, u: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(F, C, N, 3) residual of the per-frame space fit of y (F, C, N, 3), best grid entry per curve+coord."""
    yt = np.moveaxis(y, 0, 2) * mask[:, :, None, None]  # (C, N, F, 3)
    best, best_sse = None, None
    for q in _space_bases(u, mask):
        r = yt - np.matmul(q, np.matmul(np.swapaxes(q, 1, 2), yt.reshape(yt.shape[0], yt.shape[1], -1))
                           ).reshape(yt.shape)
        sse = np.einsum("cnfj,cnfj->cj", r, r)
        if best is None:
            best, best_sse = r, sse
        else:
            better = sse < best_sse
            best = np.where(better[:, None, None, :], r, best)
            best_sse = np.minimum(sse, best_sse)
    return np.moveaxis(best, 2, 0)


def curve_floor(
    frames: np.ndarray, curves: CurveSet, motion: str = "displacement"
) -> tuple[np.ndarray, np.ndarray]:
    """(C,) sum of squared errors and (C,) max error of every curve; curves need not cover every vertex.

    frames : (F, V, 3) float; the chord parameter comes from frame 0.
    """
    if motion not in MOTIONS:
        raise ParameterError(f"motion must be one of {MOTIONS}, got {motion!r}")
    idx, mask = curves.padded()
    c = len(idx)
    sq, mx = np.zeros(c), np.zeros(c)
    if c == 0:
        return sq, mx
    u = chord_parameters(frames[0].astype(np.float64), idx, mask)
    step = max(1, CHUNK_VALUES // max(1, idx.shape[1] * frames.shape[0] * 3))
    for lo in range(0, c, step):
        sl = slice(lo, min(c, lo + step))
        r = chunk_residual(motion_targets(frames, idx[sl], mask[sl], motion), u[sl], mask[sl])
        e2 = np.einsum("fcnj,fcnj->fcn", r, r) * mask[sl]
        sq[sl] = e2.sum(axis=(0, 2))
        mx[sl] = np.sqrt(e2.max(axis=(0, 2)))
    return sq, mx


def bbox_diagonal(points: np.ndarray) -> float:
    """Bounding-box diagonal of (V, 3) points, 1.0 when empty or flat to a point (errors stay absolute)."""
    diag = float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0
    return diag if diag > 0 else 1.0


def spatial_floor(frames: np.ndarray, curves: CurveSet, motion: str = "displacement") -> FloorReport:
    """Floor of fitting frames (F, V, 3) frame by frame with the curves' space basis, for one motion
    variant."""
    if motion not in MOTIONS:
        raise ParameterError(f"motion must be one of {MOTIONS}, got {motion!r}")
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise ParameterError(f"frames must have shape (F, V, 3), got {frames.shape}")
    curves.validate(frames.shape[1])
    sq, mx = curve_floor(frames, curves, motion)
    count = curves.lengths * frames.shape[0]
    diag = bbox_diagonal(frames[0])
    rms = float(np.sqrt(sq.sum() / max(1, count.sum())))
    mxa = float(mx.max()) if len(mx) else 0.0
    return FloorReport(motion, rms, mxa, rms / diag, mxa / diag, diag,
                       np.sqrt(sq / np.maximum(count, 1)), mx)
