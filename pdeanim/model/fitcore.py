"""Variable-projection fit of all items (curve x coordinate) at once: space stage, then time stage.

Items are rows k = 3 c + w of padded curve data. The space stage (kind, D per item) runs once per fit; the
time stage (segments, knots, constants) reruns for every segmentation the adaptive search tries.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .knotbasis import SharedWeights
from .segments import Segmentation
from .spacefit import SpaceProjection, project_items, search_D
from .timefit import CUBIC_SLACK, fit_tracks, fit_tracks_spline, predict


@dataclass
class SpaceStage:
    """Per-item space fit: projection, projected tracks b (K, F, 4), floor energy per item and frame (K, F),
    the item data Yk (K, F, N) float64 it was fitted to (for per-point residuals; may be a strided view),
    and which items the time stage may fit as natural-spline tracks (and the slack they get)."""

    proj: SpaceProjection
    b: np.ndarray
    floor_frames: np.ndarray
    Yk: np.ndarray | None = None
    spline_candidates: np.ndarray | None = None  # (K,) bool; None: the paper's time model only
    spline_slack: float = CUBIC_SLACK
    shared_weights: SharedWeights | None = None  # knot weights a windowed fit's windows share (format §3.4)


@dataclass
class TimeStage:
    """Per-item time fit: balanced space-coefficient knots a (K, S + 1, 4), constants mu (K, S), errors."""

    segm: Segmentation
    knots: np.ndarray
    mu: np.ndarray
    err_frames: np.ndarray  # (K, F) squared error per item and frame (floor included)
    pred: np.ndarray  # (K, F, 4) model tracks in orthonormal coordinates
    spline: np.ndarray | None = None  # (K,) bool natural-spline tracks, None: none
    cache: dict[str, Any] = field(default_factory=dict)  # work on these knots that no rounding changes


def items_from_curves(values: np.ndarray, idx: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Padded item data (F, K, N) float64 from per-vertex values (F, V, 3) and padded curves (C, N).

    One gather along the flattened (vertex, coordinate) axis; padding points are zero.
    """
    values = np.asarray(values, dtype=np.float64)
    F = values.shape[0]
    flat = (idx[:, None, :] * 3 + np.arange(3)[None, :, None]).reshape(-1)  # item k = 3 c + w, point n
    Y = np.take(values.reshape(F, -1), flat, axis=1).reshape(F, -1, idx.shape[1])
    Y *= np.repeat(mask, 3, axis=0)
    return Y


def items_to_vertices(items: np.ndarray, idx: np.ndarray, mask: np.ndarray, n_vertices: int) -> np.ndarray:
    """Inverse of :func:`items_from_curves`: (F, K, N) -> (F, V, 3) float64."""
    F, K, N = items.shape
    c, n = np.nonzero(mask)
    flat = ((3 * c)[:, None] + np.arange(3)) * N + n[:, None]  # (M, 3) positions in the flattened items
    out = np.zeros((F, n_vertices, 3))
    out[:, idx[c, n]] = np.take(items.reshape(F, K * N), flat, axis=1)
    return out


def vertex_slots(idx: np.ndarray, mask: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V,) int64 slot c * N + n of every vertex in the padded curves (C, N) (each vertex on one curve)."""
    slots = np.zeros(n_vertices, dtype=np.int64)
    c, n = np.nonzero(mask)
    slots[idx[c, n]] = c * idx.shape[1] + n
    return slots


def point_distances(resid: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """(F, V) Euclidean lengths of item residuals resid (K, F, N) at the vertices' slots (see
    vertex_slots)."""
    K, F, N = resid.shape
    r = resid.reshape(K // 3, 3, F, N)
    sq = r[:, 0] * r[:, 0]
    sq += r[:, 1] * r[:, 1]  # same summation order as np.linalg.norm over (x, y, z)
    sq += r[:, 2] * r[:, 2]
    return np.sqrt(np.take(np.moveaxis(sq, 1, 0).reshape(F, -1), slots, axis=1))


def model_distances(space: SpaceStage, time: TimeStage, slots: np.ndarray) -> np.ndarray:
    """(F, V) model-to-data distances of a fit at every fitted frame (float64)."""
    return point_distances(time.pred @ np.swapaxes(space.proj.U, 1, 2) - space.Yk, slots)


def floor_distances(space: SpaceStage, slots: np.ndarray) -> np.ndarray:
    """(F, V) distances left by the space basis alone (the data minus its projection)."""
    return point_distances(space.Yk - space.b @ np.swapaxes(space.proj.U, 1, 2), slots)


def space_stage(Y: np.ndarray, u: np.ndarray, mask: np.ndarray) -> SpaceStage:
    """Choose (kind, D) per item on the spatial floor and project every frame: Y (F, K, N), u/mask (K, N)."""
    Yk = np.moveaxis(Y, 0, 1)  # (K, F, N) view: matmul reads its (F, N) blocks in place, no reordering copy
    gram = np.swapaxes(Yk, 1, 2) @ Yk
    kind_i, D, _ = search_D(u, mask, gram, check_cond=False)
    proj = project_items(u, mask, kind_i, D, fallback=True)  # the condition check reuses the projection SVD
    b = Yk @ proj.U
    floor = np.maximum(np.einsum("kfn,kfn->kf", Yk, Yk) - np.einsum("kfa,kfa->kf", b, b), 0.0)
    return SpaceStage(proj, b, floor, Yk)


def time_stage(space: SpaceStage, segm: Segmentation, loop: bool = False, refine_iters: int = 5) -> TimeStage:
    """Fit knot tracks (the paper's time pairs, or the natural spline for the space stage's candidates where
    it fits as well) for one segmentation; errors per item and frame include the spatial floor."""
    spline = None
    if space.spline_candidates is not None and space.spline_candidates.any() and not loop:
        z, mu, spline = fit_tracks_spline(space.b, segm, space.spline_candidates, refine_iters=refine_iters,
                                          slack=space.spline_slack)
    else:
        z, mu = fit_tracks(space.b, segm, loop, refine_iters=refine_iters)
    pred = predict(z, segm, mu, spline)
    d = space.b - pred
    err = space.floor_frames + np.einsum("kfa,kfa->kf", d, d)  # einsum: a sum over axis -1 is ~5x slower
    knots = np.einsum("kab,ksb->ksa", space.proj.to_coef, z)
    return TimeStage(segm, knots, mu, err, pred, spline)


def reconstruct_items(space: SpaceStage, time: TimeStage) -> np.ndarray:
    """Model item values (F, K, N) float64 at the fitted frames."""
    return np.moveaxis(time.pred @ np.swapaxes(space.proj.U, 1, 2), 1, 0)
