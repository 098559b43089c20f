"""Skinning decomposition of an unskinned sequence (SSDR, in the manner of Le and Deng's smooth skinning
decomposition and Dem Bones): bones initialised by clustering the welded vertex trajectories and refining the
clusters by their rigid motion, then alternately the weights (at most 4 per vertex, non-negative, summing to
1) and the bone transforms (per bone, a weighted Kabsch fit vectorised over frames)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rigid import moved, single_bone_errors, weighted_kabsch
from .weights import solve_weights

INFLUENCES = 4
CLUSTER_FRAMES = 16
"""Frames (evenly spaced) whose positions are the features of the trajectory clustering."""
KMEANS_ROUNDS = 8
RIGID_ROUNDS = 6
"""Rounds of re-assigning every point to the bone whose rigid motion predicts its trajectory best."""
ITERATIONS = 12
"""Alternations of the weight and transform updates."""


@dataclass
class Decomposition:
    """Bones of welded points: rest (P, 3), index/weight (P, K) (weights sum to 1, largest first), rotations
    (F, B, 3, 3) and translations (F, B, 3) acting as x -> R x + t, and each point's squared skinning error
    summed over frames (P,)."""

    rest: np.ndarray
    index: np.ndarray
    weight: np.ndarray
    R: np.ndarray
    t: np.ndarray
    point_sq: np.ndarray

    @property
    def rms(self) -> float:
        """RMS distance of the skinned points to their trajectories, over all frames."""
        return float(np.sqrt(self.point_sq.sum() / (self.R.shape[0] * len(self.rest))))

    def skin(self) -> np.ndarray:
        """(F, P, 3) the skinned positions of the points."""
        out = np.zeros((self.R.shape[0], *self.rest.shape))
        for k in range(self.index.shape[1]):
            b = self.index[:, k]
            moved = np.einsum("fvij,vj->fvi", self.R[:, b], self.rest) + self.t[:, b]
            out += self.weight[None, :, k, None] * moved
        return out


def decompose(frames: np.ndarray, bones: int, iterations: int = ITERATIONS,
              influences: int = INFLUENCES, sparse_rms: float = 0.0) -> Decomposition:
    """SSDR of frames (F, P, 3) (distinct trajectories; the rest pose is frame 0) with ``bones`` bones (at
    most the points). ``sparse_rms`` > 0: after the first alternation each point keeps the fewest influences
    whose RMS distance over frames is within this (in quadrature) of its best with all of them (zero weights
    compress to almost nothing in the bone layer). Deterministic."""
    X = np.asarray(frames, np.float64)
    F, P = X.shape[:2]
    B = max(1, min(int(bones), P))
    rest = X[0]
    Xt = np.ascontiguousarray(np.swapaxes(X, 0, 1))  # (P, F, 3): a point's trajectory is a row
    labels = _kmeans(Xt, B)
    labels, R, t = _rigid_clusters(Xt, rest, labels, B)
    index = labels[:, None]
    weight = np.ones((P, 1))
    for i in range(iterations):
        sparse_ms = float(sparse_rms) ** 2 if i > 0 else 0.0
        index, weight = solve_weights(Xt, rest, R, t, index, weight, influences, sparse_ms)
        R, t = _update_transforms(Xt, rest, R, t, index, weight)
    R[0], t[0] = np.eye(3), 0.0  # frame 0 is the rest pose: every bone at identity, exactly
    dec = Decomposition(rest, index, weight, R, t, np.zeros(P))
    dec.point_sq = np.sum((dec.skin() - X) ** 2, axis=(0, 2))
    return dec


def _kmeans(Xt: np.ndarray, B: int) -> np.ndarray:
    """(P,) cluster of every trajectory (Xt (P, F, 3)): k-means on the positions at a few frames, seeded by
    farthest points (deterministic)."""
    P, F = Xt.shape[:2]
    pick = np.unique(np.round(np.linspace(0, F - 1, min(F, CLUSTER_FRAMES))).astype(np.int64))
    feat = Xt[:, pick].reshape(P, -1)
    seeds = [int(np.argmax(np.sum((feat - feat.mean(0)) ** 2, axis=1)))]
    d = np.sum((feat - feat[seeds[0]]) ** 2, axis=1)
    for _ in range(1, B):
        seeds.append(int(np.argmax(d)))
        d = np.minimum(d, np.sum((feat - feat[seeds[-1]]) ** 2, axis=1))
    centres = feat[seeds]
    ff = np.sum(feat * feat, axis=1)
    for _ in range(KMEANS_ROUNDS):
        dist = ff[:, None] - 2 * feat @ centres.T + np.sum(centres * centres, axis=1)[None]
        labels = np.argmin(dist, axis=1)
        counts = np.bincount(labels, minlength=B)
        sums = np.zeros_like(centres)
        np.add.at(sums, labels, feat)
        filled = counts > 0
        centres[filled] = sums[filled] / counts[filled, None]
    return labels


def _rigid_clusters(Xt: np.ndarray, rest: np.ndarray, labels: np.ndarray, B: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clusters refined by their rigid motion: fit each cluster's transforms, move every point to the bone
    that predicts it best; an emptied bone is re-seeded at the worst-fitted point."""
    for _ in range(RIGID_ROUNDS):
        R, t = _cluster_transforms(Xt, rest, labels, B)
        err = single_bone_errors(Xt, rest, R, t)
        labels = np.argmin(err, axis=1)
        worst = np.argsort(-err[np.arange(len(labels)), labels], kind="stable")
        empty = np.flatnonzero(np.bincount(labels, minlength=B) == 0)
        labels[worst[:len(empty)]] = empty
    return labels, *_cluster_transforms(Xt, rest, labels, B)


def _cluster_transforms(Xt: np.ndarray, rest: np.ndarray, labels: np.ndarray, B: int
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transforms (F, B, 3, 3), (F, B, 3) of every cluster (its points' plain Kabsch fit)."""
    F = Xt.shape[1]
    R = np.empty((F, B, 3, 3))
    t = np.empty((F, B, 3))
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(B + 1))
    for b in range(B):
        v = order[bounds[b]:bounds[b + 1]]
        R[:, b], t[:, b] = weighted_kabsch(rest[v], np.ones(len(v)), Xt[v])
    return R, t


def _update_transforms(Xt: np.ndarray, rest: np.ndarray, R: np.ndarray, t: np.ndarray, index: np.ndarray,
                       weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One sweep over the bones: each bone's transforms refitted to what the others leave of its points
    (the skinned positions kept up to date as bones change)."""
    R, t = R.copy(), t.copy()
    B, K = t.shape[1], index.shape[1]
    flat = index.ravel()
    order = np.argsort(flat, kind="stable")
    bounds = np.searchsorted(flat[order], np.arange(B + 1))
    members = []
    for b in range(B):
        slots = order[bounds[b]:bounds[b + 1]]
        w = weight.ravel()[slots]
        members.append((slots[w > 0] // K, w[w > 0]))
    S = np.zeros_like(Xt)
    for b, (v, w) in enumerate(members):
        S[v] += w[:, None, None] * moved(R[:, b], t[:, b], rest[v])
    for b, (v, w) in enumerate(members):
        if not len(v):
            continue
        p = rest[v]
        old = moved(R[:, b], t[:, b], p)
        q = Xt[v] - S[v] + w[:, None, None] * old  # the target of w (R p + t)
        R[:, b], t[:, b] = weighted_kabsch(p, w, q)
        S[v] += w[:, None, None] * (moved(R[:, b], t[:, b], p) - old)
    return R, t
