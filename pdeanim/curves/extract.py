"""Partition every vertex of a mesh into ordered curves that run smoothly along the surface.

Method (chosen by measuring the spatial floor and turning angles against greedy edge paths and banded
iso-lines, see docs/model.md, "Curve extraction"): weld seams by position (connectivity only), compute a
smooth scalar field per connected component (:mod:`pdeanim.curves.fields`), link mesh edges into chains that
follow the field's gradient ("meridians") or its iso-lines ("rings") (:mod:`pdeanim.curves.chains`), and cut
every chain into near-equal runs of about ``target_points`` welded points. Copies of a welded point follow
each
other on one curve, so a curve's distinct positions never repeat.
"""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet
from ..errors import ParameterError
from .chains import chain_order
from .fields import FIELDS, scalar_field
from .weld import WeldedGraph, weld_graph

DEFAULT_FIELD = "fiedler"
METHODS = ("meridians", "rings")


def extract_curves(vertices: np.ndarray, faces: np.ndarray | None, *, target_points: int = 10,
                   field: str = "auto", seed: int = 0, method: str = "meridians") -> CurveSet:
    """Curves over all vertices (V, 3) float64 of a mesh with faces (T, 3) int; every vertex on one curve.

    target_points : about how many distinct positions each curve gets (chains are cut as evenly as possible)
    field : "auto" (= "fiedler"), "axis", "fiedler" or "geodesic" (see :mod:`pdeanim.curves.fields`)
    method : "meridians" (curves along the field's gradient) or "rings" (along its iso-lines)
    seed : seed of the eigen-solver's start vector (results are deterministic for a given seed)
    """
    field = DEFAULT_FIELD if field == "auto" else field
    if field not in FIELDS:
        raise ParameterError(f"field must be one of auto, {', '.join(FIELDS)}; got {field!r}")
    if method not in METHODS:
        raise ParameterError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    if (
        isinstance(target_points, bool)
        or not isinstance(target_points, int | np.integer)
        or target_points < 1
    ):
        raise ParameterError(f"target_points must be an integer >= 1, got {target_points!r}")
    g = weld_graph(vertices, faces)
    if g.n_points == 0:
        return CurveSet(np.zeros(0, np.int32), np.zeros(1, np.int32))
    f = scalar_field(g, field, seed)
    point_order, starts = chain_order(g, f, "meridian" if method == "meridians" else "ring")
    return expand_to_vertices(g, point_order, cut_runs(starts, g.n_points, target_points))


def cut_runs(starts: np.ndarray, n_points: int, target_points: int) -> np.ndarray:
    """(C + 1,) start of every curve in the chain order: each chain (K + 1,) cut into near-equal runs."""
    cnt = np.diff(starts)
    k = np.maximum(1, np.rint(cnt / target_points)).astype(np.int64)
    chain = np.repeat(np.arange(len(cnt)), cnt)
    pos = np.arange(n_points) - starts[chain]
    run = pos * k[chain] // cnt[chain]
    new = np.r_[True, (chain[1:] != chain[:-1]) | (run[1:] != run[:-1])]
    return np.r_[np.flatnonzero(new), n_points]


def expand_to_vertices(g: WeldedGraph, point_order: np.ndarray, run_start: np.ndarray) -> CurveSet:
    """CurveSet over the original vertices: copies of a welded point follow each other (by vertex id)."""
    ppos = np.empty(g.n_points, np.int64)
    ppos[point_order] = np.arange(g.n_points)
    vpos = ppos[g.weld]
    vorder = np.lexsort((np.arange(len(g.weld)), vpos))
    curve_of_pos = np.repeat(np.arange(len(run_start) - 1), np.diff(run_start))
    vcurve = curve_of_pos[vpos[vorder]]
    offsets = np.r_[0, np.flatnonzero(vcurve[1:] != vcurve[:-1]) + 1, len(vorder)]
    return CurveSet(vorder.astype(np.int32), offsets.astype(np.int32))
