"""Baseline extraction by greedy edge paths, the approach the smooth extraction is measured against.

A path starts at the lowest unvisited welded point and keeps stepping to the unvisited neighbour that turns
least, until it has ``target_points`` points or is stuck. Per-point Python loop: a baseline for benchmarks
and tests on small meshes, not for production use.
"""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet
from .extract import expand_to_vertices
from .weld import weld_graph


def greedy_edge_curves(
    vertices: np.ndarray, faces: np.ndarray | None, *, target_points: int = 10
) -> CurveSet:
    """Curves (CurveSet over all V vertices) made of greedy straightest edge paths of up to target_points."""
    g = weld_graph(vertices, faces)
    adj = g.adjacency().tocsr()
    visited = np.zeros(g.n_points, bool)
    order, starts = [], []
    for seed in range(g.n_points):
        if visited[seed]:
            continue
        starts.append(len(order))
        path = [seed]
        visited[seed] = True
        while len(path) < target_points:
            nb = adj.indices[adj.indptr[path[-1]]:adj.indptr[path[-1] + 1]]
            nb = nb[~visited[nb]]
            if len(nb) == 0:
                break
            d = g.points[nb] - g.points[path[-1]]
            if len(path) > 1:
                prev = g.points[path[-1]] - g.points[path[-2]]
                score = -(d @ prev) / np.maximum(np.linalg.norm(d, axis=1) * np.linalg.norm(prev), 1e-300)
            else:
                score = np.linalg.norm(d, axis=1)
            nxt = int(nb[np.lexsort((nb, score))[0]])
            path.append(nxt)
            visited[nxt] = True
        order += path
    run_start = np.array(starts + [g.n_points], np.int64)
    return expand_to_vertices(g, np.array(order, np.int64), run_start)
