"""From a decomposition of welded trajectories to the bone layer's :class:`BoneMotion` on every vertex: welded
points hand their influences back to their vertices, unused bones are dropped, and every bone turns about a
pivot at the weighted centroid of its vertices at rest so that its translations stay small."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.bonelayer import BoneMotion
from .decompose import INFLUENCES, ITERATIONS, Decomposition, decompose
from .trajweld import weld_trajectories


def fitted_bones(frames: np.ndarray, bones: int, iterations: int = ITERATIONS,
                 influences: int = INFLUENCES, sparse_rms: float = 0.0) -> tuple[BoneMotion, float]:
    """The bone motion of frames (F, V, 3) (rest pose: frame 0) by a skinning decomposition with at most
    ``bones`` bones and ``influences`` per vertex on the welded trajectories (``sparse_rms``: see
    :func:`~pdeanim.bones.decompose.decompose`), and the skinning's RMS error per vertex over all frames."""
    welded = weld_trajectories(frames)
    X = np.asarray(frames, np.float64)[:, welded.keep]
    dec = decompose(X, bones, iterations, influences, sparse_rms)
    counts = np.bincount(welded.point_of, minlength=welded.n_points)
    rms = float(np.sqrt((dec.point_sq * counts).sum() / (X.shape[0] * len(welded.point_of))))
    return to_motion(dec, welded.point_of), rms


def to_motion(dec: Decomposition, point_of: np.ndarray) -> BoneMotion:
    """The BoneMotion of a decomposition on the vertices (``point_of`` (V,): the welded point of each)."""
    index, weight = dec.index[point_of], dec.weight[point_of]
    used = np.unique(index[weight > 0])
    renumber = np.zeros(dec.t.shape[1], np.int64)
    renumber[used] = np.arange(len(used))
    index = np.where(weight > 0, renumber[index], 0)
    R, t = dec.R[:, used], dec.t[:, used]
    pivot = pivots(dec.rest[point_of], index, weight, len(used))
    F, B = t.shape[:2]
    rotvec = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(F, B, 3)
    translation = np.einsum("fbij,bj->fbi", R, pivot) + t - pivot[None]  # R x + t = R (x - c) + c + T
    return BoneMotion(pivot, index, weight, rotvec, translation)


def pivots(rest: np.ndarray, index: np.ndarray, weight: np.ndarray, n_bones: int) -> np.ndarray:
    """(B, 3) each bone's weighted centroid of the rest positions (V, 3) it moves (the rest pose's centroid
    for a bone that moves none)."""
    w = np.zeros(n_bones)
    s = np.zeros((n_bones, 3))
    np.add.at(w, index.ravel(), weight.ravel())
    np.add.at(s, index.ravel(), (weight[..., None] * rest[:, None]).reshape(-1, 3))
    centre = rest.mean(axis=0) if len(rest) else np.zeros(3)
    return np.where(w[:, None] > 0, s / np.maximum(w, 1e-300)[:, None], centre)
