"""The space half of a fit: curves (extracted automatically, or given), shortened and split until their
spatial floor leaves room for the targets, the space stage of the model on them, and which items may take the
natural-spline time model."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..curves.extract import extract_curves
from ..curves.split import split_curves
from ..curveset import CurveSet
from ..errors import PosesInputError
from ..model.adaptive import Targets
from ..model.fitcore import SpaceStage, floor_distances, space_stage
from ..model.metrics import bbox_diagonal
from ..model.spline import prefer_spline
from ..poses import Poses
from ..progress import Progress
from .options import FitOptions, FitTolerances
from .problem import Problem, prepare


@dataclass
class SpaceFit:
    """The space stage of a fit and what it was measured on."""

    p: Problem
    curves: CurveSet
    space: SpaceStage
    floor_d: np.ndarray  # (F, V) distance left by the space basis alone
    targets: Targets
    diag: float
    curve_points: int | None
    splits: int = 0


def default_curves(rest: np.ndarray, faces: np.ndarray, curve_points: int = 10) -> CurveSet:
    """Curves of :func:`pdeanim.curves.extract.extract_curves` for the rest pose (V, 3) and faces (T, 3)."""
    return extract_curves(np.asarray(rest, np.float64), faces if len(faces) else None,
                          target_points=curve_points)


def space_fit(poses: Poses, options: FitOptions, curves: CurveSet | None, progress: Progress,
              tol: FitTolerances) -> SpaceFit:
    """Curves + space stage; automatic curves get shorter until the spatial floor's RMS leaves room for the
    target, then the curves whose floor exceeds the per-vertex bound are split (tol.split_rms_ratio)."""
    auto = curves is None
    for cp in _curve_point_ladder(options.curve_points if auto else None):
        progress(0.02, f"curves {cp or 'given'}")
        cs = checked_curves(default_curves(poses.rest_pose(), poses.faces, cp) if auto else curves,
                            poses.n_vertices)
        p, space, floor_d = space_of(poses, options, cs, progress, tol)
        diag = bbox_diagonal(p.rest)
        targets = options.targets(diag)
        if options.segments or _floor_leaves_room(floor_d, targets, tol):
            break
    splits = 0
    bound = None if options.segments or not auto else _curve_floor_bound(targets, tol)
    for _ in range(tol.split_rounds if bound is not None else 0):
        bad = _curve_max(cs, floor_d) > bound
        new = split_curves(p.rest, cs, bad) if bad.any() else cs
        if new.n_curves == cs.n_curves:
            break
        splits += new.n_curves - cs.n_curves
        progress(0.06, f"split {new.n_curves - cs.n_curves} curves")
        cs = new
        del p, space, floor_d  # one problem held at a time
        p, space, floor_d = space_of(poses, options, cs, progress, tol)
    return SpaceFit(p, cs, space, floor_d, targets, diag, cp, splits)


def space_of(poses: Poses, options: FitOptions, cs: CurveSet, progress: Progress, tol: FitTolerances
             ) -> tuple[Problem, SpaceStage, np.ndarray]:
    """Problem, space stage (with its natural-spline candidates) and floor distances (F, V) of one curve
    set."""
    p = prepare(poses, options, cs)
    K, N = p.Y.shape[1], p.Y.shape[2]
    progress(0.05, "space fit")
    space = space_stage(p.Y, p.u.reshape(K, N), np.repeat(p.mask, 3, axis=0))
    if not options.loop and options.time_model == "auto":
        space.spline_candidates = prefer_spline(space.b, p.t, tol.cubic_gain)
        space.spline_slack = tol.cubic_slack
    elif not options.loop and options.time_model == "spline":
        space.spline_candidates = np.ptp(space.b, axis=1).any(axis=-1)  # every moving item
        space.spline_slack = np.inf
    return p, space, floor_distances(space, p.slots)


def checked_curves(curves: CurveSet, n_vertices: int) -> CurveSet:
    """The curves as int32 arrays, validated against the poses' vertex count (PosesInputError if not)."""
    curves = CurveSet(np.asarray(curves.order, np.int32), np.asarray(curves.offsets, np.int32))
    try:
        return curves.validate(n_vertices)
    except Exception as exc:
        raise PosesInputError(f"curves do not match the poses: {exc}") from exc


def _curve_max(cs: CurveSet, d: np.ndarray) -> np.ndarray:
    """(C,) largest distance (F, V) on each curve."""
    out = np.zeros(cs.n_curves)
    np.maximum.at(out, cs.curve_of_vertex(d.shape[1])[0], d.max(axis=0))
    return out


def _curve_floor_bound(targets: Targets, tol: FitTolerances) -> float | None:
    """The most a curve's spatial floor may leave at any vertex before it is split in two."""
    bounds = []
    if targets.max is not None:
        bounds.append(tol.floor_max_share * targets.max)
    if targets.rms is not None and tol.split_rms_ratio is not None:
        bounds.append(tol.split_rms_ratio * targets.rms)
    return min(bounds) if bounds else None


def _curve_point_ladder(start: int | None) -> list[int | None]:
    """Curve lengths tried when curves are extracted automatically: shorter until the floor leaves room."""
    if start is None:
        return [None]
    ladder = [start]
    while ladder[-1] > 3:
        ladder.append(max(3, int(round(ladder[-1] * 0.7))))
    return ladder


def _floor_leaves_room(floor_d: np.ndarray, targets: Targets, tol: FitTolerances) -> bool:
    """Whether the spatial floor's RMS is far enough below an RMS target for the time fit to meet it (a max
    target is left to splitting the curves that exceed it)."""
    return bool(targets.rms is None or np.sqrt(np.mean(floor_d * floor_d)) <= tol.floor_room * targets.rms)
