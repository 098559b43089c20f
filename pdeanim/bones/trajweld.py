"""Welding trajectories: vertices whose positions agree in every frame (seam duplicates of a glTF or OBJ mesh)
move as one, so a decomposition solves each distinct trajectory once."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WeldedTrajectories:
    """``keep`` (P,): the first vertex of each distinct trajectory (ascending); ``point_of`` (V,): the welded
    point of every vertex."""

    keep: np.ndarray
    point_of: np.ndarray

    @property
    def n_points(self) -> int:
        return len(self.keep)


def weld_trajectories(frames: np.ndarray) -> WeldedTrajectories:
    """Group the vertices of frames (F, V, 3) whose float32 positions are equal in every frame."""
    X = np.ascontiguousarray(np.swapaxes(np.asarray(frames, np.float32), 0, 1))  # (V, F, 3)
    V = X.shape[0]
    rows = X.reshape(V, -1).view(np.uint8)
    void = np.ascontiguousarray(rows).view(np.dtype((np.void, rows.shape[1]))).reshape(-1)
    _, first, inverse = np.unique(void, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # points numbered by their first vertex
    rank = np.empty(len(first), np.int64)
    rank[order] = np.arange(len(first))
    return WeldedTrajectories(np.sort(first).astype(np.int64), rank[inverse.reshape(-1)])
