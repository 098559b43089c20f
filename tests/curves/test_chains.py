"""Chain linking: pointer-jumping ranks, ring cutting and mutual matching."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.curves.chains import rank_chains, vertex_directions
from pdeanim.curves.fields import scalar_field
from pdeanim.curves.weld import weld_graph


def test_rank_chains_cuts_rings_at_lowest_point():
    # ring 2 -> 0 -> 1 -> 2, path 3 -> 4, singleton 5
    succ = np.array([1, 2, 0, 4, -1, -1])
    pred = np.array([2, 0, 1, -1, 3, -1])
    head, rank, s2, p2 = rank_chains(succ, pred)
    assert head.tolist() == [0, 0, 0, 3, 3, 5]
    assert rank.tolist() == [0, 1, 2, 0, 1, 0]
    assert p2[0] == -1 and s2[2] == -1


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 60), seed=st.integers(0, 1000))
def test_rank_chains_on_random_permutation_links(n, seed):
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n)
    keep = rng.random(n) < 0.8  # link perm[i] -> perm[i + 1] with some links dropped, last may close a ring
    succ, pred = np.full(n, -1), np.full(n, -1)
    for i in range(n):
        j = (i + 1) % n
        if keep[i] and (j != 0 or rng.random() < 0.5) and n > 1:
            succ[perm[i]], pred[perm[j]] = perm[j], perm[i]
    head, rank, s2, p2 = rank_chains(succ, pred)
    # every point reaches its head by following pred exactly rank times
    for v in range(n):
        x = v
        for _ in range(rank[v]):
            x = p2[x]
        assert x == head[v] and p2[x] == -1
    order = np.lexsort((rank, head))
    assert sorted(order.tolist()) == list(range(n))


def test_directions_are_unit_and_tangent(spot):
    v, f = spot
    g = weld_graph(v, f)
    field = scalar_field(g, "fiedler")
    for along in ("ring", "meridian"):
        d = vertex_directions(g, field, along)
        norm = np.linalg.norm(d, axis=1)
        assert np.all((np.abs(norm - 1) < 1e-9) | (norm == 0)) and np.mean(norm > 0) > 0.95
