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


def partitioned_colors(
    tets: np.ndarray, points: np.ndarray, parts: int
) -> tuple[list[np.ndarray], np.ndarray]:
    """Colour classes in solve order and the colour bounds (P + 1,) int64 of ``parts`` independent groups.

    Slabs along the longest axis with equal tet counts: the tets whose four points all lie in slab p form part
    p (parts share no point, so they may be solved at the same time); the tets that straddle slabs come last.
    Colours bounds[p]:bounds[p + 1] belong to part p, colours bounds[-1]: to the straddling tets. With parts
    < 2 everything is one part. Deterministic.
    """
    if parts < 2:
        colors = color_tets(tets, len(points))
        return colors, np.array([0, len(colors)], np.int64)
    axis = int(np.argmax(np.ptp(points, axis=0)))
    cuts = np.quantile(points[tets, axis].mean(axis=1), np.arange(1, parts) / parts)
    side = np.searchsorted(cuts, points[:, axis])[tets]  # (M, 4) slab of each corner
    inner = np.all(side == side[:, :1], axis=1)
    groups = [np.flatnonzero(inner & (side[:, 0] == p)) for p in range(parts)] + [np.flatnonzero(~inner)]
    colors: list[np.ndarray] = []
    bounds = [0]
    for g in groups:
        colors += [g[c] for c in color_tets(tets[g], len(points))]
        bounds.append(len(colors))
    return colors, np.asarray(bounds[:-1], np.int64)
