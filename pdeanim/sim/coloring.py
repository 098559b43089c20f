"""Colour tets so that no two tets of one colour share a point (Gauss-Seidel one colour at a time)."""

from __future__ import annotations

import numpy as np


def color_tets(tets: np.ndarray, n_points: int) -> list[np.ndarray]:
    """Deterministic greedy colouring of (M, 4) tets; returns one sorted (K_c,) int64 index array per colour.

    Each round claims, for every free point, the lowest-numbered uncoloured tet touching it; a tet that wins
    all four of its points joins the colour and blocks its points. Rounds repeat until the colour is maximal.
    """
    m = len(tets)
    remaining = np.arange(m)
    colors: list[np.ndarray] = []
    big = np.iinfo(np.int64).max
    while len(remaining):
        blocked = np.zeros(n_points, bool)
        members = []
        candidates = remaining
        while len(candidates):
            owner = np.full(n_points, big, np.int64)
            np.minimum.at(owner, tets[candidates].ravel(), np.repeat(candidates, 4))
            won = np.all(owner[tets[candidates]] == candidates[:, None], axis=1)
            chosen = candidates[won]
            members.append(chosen)
            blocked[tets[chosen].ravel()] = True
            candidates = candidates[~won]
            candidates = candidates[~blocked[tets[candidates]].any(axis=1)]
        color = np.sort(np.concatenate(members))
        colors.append(color)
        remaining = np.setdiff1d(remaining, color, assume_unique=True)
    return colors
