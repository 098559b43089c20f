"""Motion mode "rigid": each curve's best rigid motion from the first frame, plus a residual fitted in the
curve's moving frame.

Per curve and frame, Kabsch gives R_f and the centroid c_f with x_f ~ R_f (p - c_0) + c_f. The rotation
vector and the centroid ride on the same C0 knot tracks as the residual (their own, coarser segments,
:data:`RIGID_SEGMENTS`), and the residual w_f = R_hat_f^T (x_f - c_hat_f) - (p - c_0) is taken against the
*fitted* tracks, so whatever the smooth rigid tracks miss is fitted by the PDE curves. Positions are
x(t) = R(t) (rest - c_0 + w(t)) + c(t); since R is orthogonal, |x_hat - x| = |w_hat - w|.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .families import time_pair
from .segments import Segmentation, uniform_segmentation
from .timefit import fit_tracks

RIGID_SEGMENTS = 4
"""Segments of the rigid tracks (the residual absorbs what they miss)."""


@dataclass
class RigidTracks:
    """Rigid motion of every curve: segment_t (Sr+1,), centre0 (C, 3), rotation-vector and centroid knots
    (Sr+1, C, 3) with signed time constants (Sr, C) (> 0 exp, < 0 trig, 0 linear)."""

    segment_t: np.ndarray
    centre0: np.ndarray
    rot_knots: np.ndarray
    rot_mu: np.ndarray
    trans_knots: np.ndarray
    trans_mu: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays stored in the coefficients part (float32 except the boundaries)."""
        return {
            "rigid_segment_t": self.segment_t.astype(np.float64),
            "rigid_centre": self.centre0.astype(np.float32),
            "rigid_rot_knots": self.rot_knots.astype(np.float32),
            "rigid_rot_mu": self.rot_mu.astype(np.float32),
            "rigid_trans_knots": self.trans_knots.astype(np.float32),
            "rigid_trans_mu": self.trans_mu.astype(np.float32),
        }

    @staticmethod
    def from_arrays(a: dict[str, np.ndarray]) -> RigidTracks:
        """Inverse of :meth:`arrays` (float64 copies)."""
        f = {k: np.asarray(a[k], np.float64) for k in ("rigid_segment_t", "rigid_centre", "rigid_rot_knots",
                                                       "rigid_rot_mu", "rigid_trans_knots", "rigid_trans_mu")}
        return RigidTracks(f["rigid_segment_t"], f["rigid_centre"], f["rigid_rot_knots"], f["rigid_rot_mu"],
                           f["rigid_trans_knots"], f["rigid_trans_mu"])

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation matrices (T, C, 3, 3) and centroids (T, C, 3) at normalised times t (T,)."""
        r = track_at(self.rot_knots, self.rot_mu, self.segment_t, t)
        c = track_at(self.trans_knots, self.trans_mu, self.segment_t, t)
        return rodrigues(r), c


def kabsch(
    rest: np.ndarray, frames: np.ndarray, mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best rotation per frame and curve: (R (F, C, 3, 3), centroids (F, C, 3), centre0 (C, 3)).

    rest : (C, N, 3); frames : (F, C, N, 3); mask : (C, N) bool. x_f ~ R_f (p - centre0) + centroid_f.
    Curves whose points are (nearly) collinear get the identity rotation.
    """
    w = mask[..., None].astype(np.float64)
    n = np.maximum(w.sum(axis=1), 1.0)
    c0 = (rest * w).sum(axis=1) / n
    cf = (frames * w).sum(axis=2) / n
    P = (rest - c0[:, None]) * w
    Q = (frames - cf[:, :, None]) * w
    H = np.einsum("cni,fcnj->fcij", P, Q)  # sum p q^T
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    d = np.where(d == 0, 1.0, d)
    Dm = np.ones(H.shape[:-1])
    Dm[..., 2] = d
    R = np.swapaxes(Vt, -1, -2) @ (Dm[..., None] * np.swapaxes(U, -1, -2))
    sv = np.linalg.svd(P, compute_uv=False)  # (C, 3): a curve on a line has no defined roll
    flat = (sv[:, 1] <= 1e-6 * np.maximum(sv[:, 0], 1e-300)) if sv.shape[1] > 1 else np.ones(len(sv), bool)
    R[:, flat] = np.eye(3)  # points or collinear curves: translation only (the residual takes the rest)
    return R, cf, c0


def continuous_rotvec(R: np.ndarray) -> np.ndarray:
    """(F, C, 3) rotation vectors of R (F, C, 3, 3), unwrapped over frames (no jumps of 2 pi)."""
    F, C = R.shape[:2]
    r = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(F, C, 3)
    for f in range(1, F):
        ang = np.linalg.norm(r[f], axis=-1, keepdims=True)
        axis = r[f] / np.where(ang > 0, ang, 1.0)
        best = r[f]
        for k in (-1.0, 1.0):
            alt = r[f] + k * 2 * np.pi * axis
            closer = np.linalg.norm(alt - r[f - 1], axis=-1) < np.linalg.norm(best - r[f - 1], axis=-1)
            best = np.where(closer[:, None], alt, best)
        r[f] = best
    return r


def rodrigues(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3), stable for small angles."""
    th = np.linalg.norm(r, axis=-1)[..., None, None]
    K = np.zeros(r.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -r[..., 2], r[..., 1], -r[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = r[..., 2], -r[..., 1], r[..., 0]
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    return np.eye(3) + a * K + b * (K @ K)


def track_at(knots: np.ndarray, mu: np.ndarray, segment_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Values (T, C, W) of C0 knot tracks knots (S+1, C, W), mu (S, C) at normalised times t (T,)."""
    t = np.asarray(t, np.float64)
    S = len(segment_t) - 1
    s = np.clip(np.searchsorted(segment_t, t, side="right") - 1, 0, S - 1)
    t0, t1 = segment_t[s], segment_t[s + 1]
    tau = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    m = mu[s]  # (T, C)
    phi = time_pair(np.broadcast_to(tau[:, None], m.shape), m)
    return phi[..., 0:1] * knots[s] + phi[..., 1:2] * knots[s + 1]


def fit_rigid(rest: np.ndarray, frames: np.ndarray, mask: np.ndarray, t: np.ndarray,
              loop: bool = False) -> RigidTracks:
    """Fit rigid tracks of every curve: rest (C, N, 3), frames (F, C, N, 3), mask (C, N), times t (F,)."""
    R, cf, c0 = kabsch(rest, frames, mask)
    segm = uniform_segmentation(t, RIGID_SEGMENTS) if len(t) > 1 else Segmentation(np.array([0, 0]), t)
    rv = np.moveaxis(continuous_rotvec(R), 0, 1)  # (C, F, 3)
    rz, rmu = fit_tracks(rv, segm, loop)
    tz, tmu = fit_tracks(np.moveaxis(cf, 0, 1), segm, loop)
    return RigidTracks(segm.segment_t, c0, np.moveaxis(rz, 1, 0), rmu.T, np.moveaxis(tz, 1, 0), tmu.T)


def local_residual(X: np.ndarray, rest: np.ndarray, cid: np.ndarray, tracks: RigidTracks,
                   t: np.ndarray) -> np.ndarray:
    """Residual w (F, V, 3) in each curve's moving frame: R_hat^T (x - c_hat) - (rest - c0)."""
    R, c = tracks.at(t)  # (F, C, 3, 3), (F, C, 3)
    d = X - c[:, cid]
    local = np.einsum("fvji,fvj->fvi", R[:, cid], d)
    return local - (rest - tracks.centre0[cid])
