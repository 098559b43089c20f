"""Curves as chains of mesh edges that follow a smooth direction field, built by vectorised matching.

Every welded point gets a direction (the iso-line direction of the scalar field: surface normal x gradient).
A directed edge i -> j scores how well its step follows the directions at both ends. Each point keeps its best
outgoing and best incoming edge, and mutual choices become links, so every point has at most one successor
and one predecessor: the links form disjoint chains (and closed rings, cut open at their lowest point).
Chain ends are then joined in a few rounds by the same mutual rule, scoring how straight the joined chain
continues, with the threshold relaxed each round. All steps are numpy operations over edges and points.
"""

from __future__ import annotations

import numpy as np

from .weld import WeldedGraph

JOIN_THRESHOLDS = (0.5, 0.0, -0.5)  # minimum cosine for joining chain ends, round by round
LINK_THRESHOLD = 0.5  # minimum direction score (cosine) for a first-round link


def vertex_directions(g: WeldedGraph, f: np.ndarray, along: str = "ring") -> np.ndarray:
    """(P, 3) unit iso-line ("ring") or gradient ("meridian") direction of field f (P,); zero where
    undefined."""
    p, tri = g.points, g.faces
    n = g.n_points
    if len(tri) == 0:
        return np.zeros((n, 3))
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    nrm = np.cross(b - a, c - a)
    a2 = np.linalg.norm(nrm, axis=1)
    ok = a2 > 0
    un = nrm / np.where(ok, a2, 1.0)[:, None]
    # linear-element gradient: sum_i f_i (n x e_i) / (2A), e_i the edge opposite vertex i
    grad = (f[tri[:, 0], None] * np.cross(un, c - b) + f[tri[:, 1], None] * np.cross(un, a - c)
            + f[tri[:, 2], None] * np.cross(un, b - a)) / np.where(ok, a2, 1.0)[:, None]
    vg, vn = np.zeros((n, 3)), np.zeros((n, 3))
    for k in range(3):
        np.add.at(vg, tri[:, k], grad * (0.5 * a2[:, None]))
        np.add.at(vn, tri[:, k], nrm)
    vn /= np.maximum(np.linalg.norm(vn, axis=1), 1e-300)[:, None]
    vg -= np.einsum("ij,ij->i", vg, vn)[:, None] * vn
    d = np.cross(vn, vg) if along == "ring" else vg
    size = np.linalg.norm(d, axis=1)
    ref = np.median(size[size > 0]) if np.any(size > 0) else 1.0
    return np.where((size > 1e-3 * ref)[:, None], d / np.maximum(size, 1e-300)[:, None], 0.0)


def _best_per_group(group: np.ndarray, score: np.ndarray, other: np.ndarray, n: int,
                    valid: np.ndarray) -> np.ndarray:
    """(n,) for every group id the ``other`` of its best-scoring valid entry (ties: lowest other), else -1."""
    out = np.full(n, -1, np.int64)
    sel = np.flatnonzero(valid)
    if len(sel) == 0:
        return out
    o = sel[np.lexsort((-other[sel], score[sel], group[sel]))]
    last = np.r_[group[o][1:] != group[o][:-1], True]
    out[group[o][last]] = other[o][last]
    return out


def _mutual_links(src: np.ndarray, dst: np.ndarray, score: np.ndarray, valid: np.ndarray,
                  n: int) -> tuple[np.ndarray, np.ndarray]:
    """Links src -> dst chosen by both ends: (succ, pred) arrays of length n with -1 for none."""
    fwd = _best_per_group(src, score, dst, n, valid)
    bwd = _best_per_group(dst, score, src, n, valid)
    i = np.flatnonzero(fwd >= 0)
    i = i[bwd[fwd[i]] == i]
    succ, pred = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
    succ[i] = fwd[i]
    pred[fwd[i]] = i
    return succ, pred


def rank_chains(succ: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cut rings at their lowest point, then (head, rank) of every point by pointer jumping; updates links."""
    n = len(pred)
    idx = np.arange(n)
    steps = int(np.ceil(np.log2(max(n, 2)))) + 1
    anc, low = np.where(pred >= 0, pred, idx), idx.copy()
    for _ in range(steps):
        low = np.minimum(low, low[anc])
        anc = anc[anc]
    cut = idx[(pred[anc] >= 0) & (low == idx)]  # on a ring, and its lowest point
    succ, pred = succ.copy(), pred.copy()
    succ[pred[cut]] = -1
    pred[cut] = -1
    anc, rank = np.where(pred >= 0, pred, idx), (pred >= 0).astype(np.int64)
    for _ in range(steps):
        rank = rank + rank[anc]
        anc = anc[anc]
    return anc, rank, succ, pred


def _join_round(g: WeldedGraph, succ: np.ndarray, pred: np.ndarray, thr: float,
                tangent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Join chain tails to adjacent chain heads of other chains where the chain continues straightest."""
    head, _, succ, pred = rank_chains(succ, pred)
    e = np.concatenate([g.edges, g.edges[:, ::-1]])
    t, h = e[:, 0], e[:, 1]
    ok = (succ[t] < 0) & (pred[h] < 0) & (head[t] != head[h])
    p = g.points
    step = p[h] - p[t]
    step /= np.maximum(np.linalg.norm(step, axis=1), 1e-300)[:, None]
    before = np.where((pred[t] >= 0)[:, None], p[t] - p[np.maximum(pred[t], 0)], tangent[t])
    after = np.where((succ[h] >= 0)[:, None], p[np.maximum(succ[h], 0)] - p[h], tangent[h])
    before /= np.maximum(np.linalg.norm(before, axis=1), 1e-300)[:, None]
    after /= np.maximum(np.linalg.norm(after, axis=1), 1e-300)[:, None]
    score = 0.5 * (np.einsum("ij,ij->i", before, step) + np.einsum("ij,ij->i", step, after))
    ok &= score >= thr
    s2, _ = _mutual_links(t, h, score, ok, g.n_points)
    new = s2 >= 0
    succ[new], pred[s2[new]] = s2[new], np.flatnonzero(new)
    return succ, pred


def chain_order(g: WeldedGraph, f: np.ndarray, along: str = "ring") -> tuple[np.ndarray, np.ndarray]:
    """(P,) welded points in chain order and (K + 1,) chain starts; chains follow the field's direction."""
    tangent = vertex_directions(g, f, along)
    e = np.concatenate([g.edges, g.edges[:, ::-1]])
    src, dst = e[:, 0], e[:, 1]
    step = g.points[dst] - g.points[src]
    step /= np.maximum(np.linalg.norm(step, axis=1), 1e-300)[:, None]
    score = 0.5 * np.einsum("ij,ij->i", step, tangent[src] + tangent[dst])
    succ, pred = _mutual_links(src, dst, score, score >= LINK_THRESHOLD, g.n_points)
    for thr in JOIN_THRESHOLDS:
        succ, pred = _join_round(g, succ, pred, thr, tangent)
    head, rank, _, _ = rank_chains(succ, pred)
    order = np.lexsort((rank, head))
    hs = head[order]
    starts = np.r_[0, np.flatnonzero(hs[1:] != hs[:-1]) + 1, g.n_points]
    return order, starts
