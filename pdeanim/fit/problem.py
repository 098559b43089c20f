"""The data of one fit: the poses gathered onto padded curves as items (curve x coordinate), what the curves
fit (displacement, positions or a rigid residual), and the curve parameters on their storage grid."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..curveset import CurveSet
from ..model.fitcore import items_from_curves, vertex_slots
from ..model.parameterisation import curve_parameters
from ..model.rigid import RigidTracks, fit_rigid, local_residual
from ..poses import Poses
from .options import FitOptions


@dataclass
class Problem:
    """Padded data of one fit."""

    X: np.ndarray  # (F, V, 3) float32 source positions (the poses' own array: no float64 copy is kept)
    rest: np.ndarray  # (V, 3) float64 (float32 values)
    idx: np.ndarray  # (C, N) vertex of each padded curve point
    mask: np.ndarray  # (C, N) bool real points
    u: np.ndarray  # (C, 3, N) curve parameters on the u grid
    Y: np.ndarray  # (F, K, N) float64 what the curves fit (displacement, positions or rigid residual)
    t: np.ndarray  # (F,) normalised times
    rigid: RigidTracks | None = None
    slots: np.ndarray | None = None  # (V,) slot c * N + n of every vertex in the padded curves
    curve_of: np.ndarray | None = None  # (V,) curve of every vertex

    def u_per_vertex(self) -> np.ndarray:
        """(V, 3) curve parameter of every vertex and coordinate."""
        u_v = np.zeros((self.X.shape[1], 3))
        u_v[self.idx[self.mask]] = np.moveaxis(self.u, 1, 2)[self.mask]
        return u_v


def prepare(poses: Poses, options: FitOptions, curves: CurveSet) -> Problem:
    """The padded problem of fitting ``poses`` on ``curves`` (a single frame becomes a static two-frame clip
    over a unit time span)."""
    X = np.asarray(poses.vertices, np.float32)  # float64 copies of all frames are made only transiently
    times = np.asarray(poses.times, np.float64)
    if len(X) == 1:
        X, times = np.concatenate([X, X]), np.array([times[0], times[0] + 1.0])
    rest = np.asarray(poses.rest_pose(), np.float32).astype(np.float64)
    idx, mask = curves.padded()
    u = curve_parameters(X[:, idx].astype(np.float64) if options.param_mode == "paper" else rest[idx], mask,
                         options.param_mode)
    grid = u_grid(mask.shape[1])
    u = np.rint(u / grid) * grid  # on the grid the topology part stores exactly: rounding u costs no error
    t = (times - times[0]) / (times[-1] - times[0])
    rigid = None
    if options.motion == "rigid":
        X64 = X.astype(np.float64)
        rigid = fit_rigid(rest[idx], X64[:, idx], mask, t, options.loop)
        values = local_residual(X64, rest, curves.curve_of_vertex(len(rest))[0], rigid, t)
        del X64
    else:
        values = X - rest if options.motion == "displacement" else X
    Y = items_from_curves(values, idx, mask)
    del values
    return Problem(X, rest, idx, mask, u, Y, t, rigid, vertex_slots(idx, mask, X.shape[1]),
                   curves.curve_of_vertex(X.shape[1])[0])


def u_grid(points_per_curve: int) -> float:
    """Grid of the curve parameters, applied before the fit so that the topology part stores them exactly and
    cheaply: 2^-12, or finer for long curves (at least 256 steps between evenly spaced points)."""
    return 2.0 ** -max(12, int(np.ceil(np.log2(max(points_per_curve, 1)))) + 8)


def stored_distances(p: Problem, approx: np.ndarray, n_frames: int) -> np.ndarray:
    """(F, V) distances of decoded positions (F', V, 3) to the source frames (the first ``n_frames``)."""
    return np.linalg.norm(approx[:n_frames].astype(np.float64) - p.X[:n_frames], axis=-1)
