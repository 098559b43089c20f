"""Variable-projection fit of all items (curve x coordinate) at once: space stage, then time stage.

Items are rows k = 3 c + w of padded curve data. The space stage (kind, D per item) runs once per fit; the
time stage (segments, knots, constants) reruns for every segmentation the adaptive search tries.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .segments import Segmentation
from .spacefit import SpaceProjection, project_items, search_D
from .timefit import fit_tracks, predict


@dataclass
class SpaceStage:
    """Per-item space fit: projection, projected tracks b (K, F, 4), floor energy per item and frame (K, F)."""

    proj: SpaceProjection
    b: np.ndarray
    floor_frames: np.ndarray


@dataclass
class TimeStage:
    """Per-item time fit: balanced space-coefficient knots a (K, S + 1, 4), constants mu (K, S), errors."""

    segm: Segmentation
    knots: np.ndarray
    mu: np.ndarray
    err_frames: np.ndarray  # (K, F) squared error per item and frame (floor included)
    pred: np.ndarray  # (K, F, 4) model tracks in orthonormal coordinates


def items_from_curves(values: np.ndarray, idx: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Padded item data (F, K, N) float64 from per-vertex values (F, V, 3) and padded curves (C, N)."""
    v = np.asarray(values, dtype=np.float64)[:, idx, :] * mask[None, :, :, None]  # (F, C, N, 3)
    F, C, N, _ = v.shape
    return np.moveaxis(v, 3, 2).reshape(F, C * 3, N)


def items_to_vertices(items: np.ndarray, idx: np.ndarray, mask: np.ndarray, n_vertices: int) -> np.ndarray:
    """Inverse of :func:`items_from_curves`: (F, K, N) -> (F, V, 3) float64."""
    F, K, N = items.shape
    C = K // 3
    v = np.moveaxis(items.reshape(F, C, 3, N), 2, 3)  # (F, C, N, 3)
    out = np.zeros((F, n_vertices, 3))
    out[:, idx[mask]] = v[:, mask]
    return out


def space_stage(Y: np.ndarray, u: np.ndarray, mask: np.ndarray) -> SpaceStage:
    """Choose (kind, D) per item on the spatial floor and project every frame: Y (F, K, N), u/mask (K, N)."""
    Yk = np.ascontiguousarray(np.moveaxis(Y, 0, 1))  # (K, F, N)
    gram = np.swapaxes(Yk, 1, 2) @ Yk
    kind_i, D, _ = search_D(u, mask, gram)
    proj = project_items(u, mask, kind_i, D)
    b = Yk @ proj.U
    floor = np.maximum((Yk * Yk).sum(-1) - (b * b).sum(-1), 0.0)
    return SpaceStage(proj, b, floor)


def time_stage(space: SpaceStage, segm: Segmentation, loop: bool = False, refine_iters: int = 8) -> TimeStage:
    """Fit C0 knot tracks for one segmentation; errors per item and frame include the spatial floor."""
    z, mu = fit_tracks(space.b, segm, loop, refine_iters=refine_iters)
    pred = predict(z, segm, mu)
    err = space.floor_frames + ((space.b - pred) ** 2).sum(-1)
    knots = np.einsum("kab,ksb->ksa", space.proj.to_coef, z)
    return TimeStage(segm, knots, mu, err, pred)


def reconstruct_items(space: SpaceStage, time: TimeStage) -> np.ndarray:
    """Model item values (F, K, N) float64 at the fitted frames."""
    return np.moveaxis(time.pred @ np.swapaxes(space.proj.U, 1, 2), 1, 0)
