"""Measure how well feet stay planted, honestly: every mesh vertex near the ground at rest (within
:data:`.skeleton.CONTACT` of the mesh's height) that a leg moves is part of that leg's sole, and each is
followed through the cycle in the ground's frame (the clip's positions plus the root moved forward at the
travel speed). A sole vertex is down in every frame where it is within :data:`DOWN` of the leg length of its
rest height, whether or not the gait planned a stance then. Slide: the largest horizontal drift of a vertex
from where it last touched down, over all its down frames; sink: the deepest any sole vertex goes below the
ground in any frame; height: the largest distance of a sole vertex from its rest height during the planned
stance; down: the share of frames some vertex of the sole is down."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .skeleton import CONTACT

DOWN = 0.01
"""A sole vertex is down when within this share of the leg length of its rest height."""


@dataclass(frozen=True)
class Sole:
    """The vertex indices (m,) of one foot's sole, their rest positions (m, 3) and rest heights above the
    ground (m,)."""

    vertices: np.ndarray
    rest: np.ndarray
    above: np.ndarray


def soles(skinned: Any, plan: Any, rest_vertices: np.ndarray) -> list[Sole]:
    """The sole of each leg of a :class:`pdeanim.cyclic.bodyplan.BodyPlan`: the mesh vertices near the
    ground at rest whose largest skin weight is on a joint of the leg (below its girdle, the foot and what
    hangs under it); a leg with none is measured at the lowest vertex its foot moves."""
    sk = plan.skeleton
    verts = np.asarray(rest_vertices, np.float64)
    above = verts[:, 1] - sk.ground
    near = above <= CONTACT * sk.tall
    skinned_any = skinned.vertex_weights.sum(axis=1) > 0
    owner = np.full(len(verts), -1)
    rows = np.flatnonzero(skinned_any)
    owner[rows] = skinned.vertex_joints[rows, np.argmax(skinned.vertex_weights[rows], axis=1)]
    out = []
    for leg in plan.legs:
        mask = sk.subtrees[leg.foot].copy()
        mask[list(leg.chain)] = True
        mine = (owner >= 0) & mask[np.maximum(owner, 0)]
        keep = np.flatnonzero(mine & near)
        if not len(keep):
            moved = np.flatnonzero(mine) if mine.any() else np.arange(len(verts))
            keep = moved[[int(np.argmin(verts[moved, 1]))]]
        out.append(Sole(keep, verts[keep], above[keep]))
    return out


def _unrolled(frames: np.ndarray, times: np.ndarray, period: float, sole: Sole, speed: float,
              forward: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heights above rest (K, m) and horizontal ground-frame positions (2K, m, 3) over two cycles."""
    pts = frames[:-1][:, sole.vertices].astype(np.float64)  # (K, m, 3)
    t = np.asarray(times[:-1], np.float64)
    height = (pts - sole.rest[None]) @ up
    ground = pts + (speed * t)[:, None, None] * forward
    ground = ground - (ground @ up)[..., None] * up
    return height, np.concatenate([ground, ground + speed * period * forward])


def foot_figures(frames: np.ndarray, times: np.ndarray, period: float, stance: np.ndarray, sole: Sole,
                 speed: float, forward: np.ndarray, up: np.ndarray, leg_length: float) -> dict[str, Any]:
    """Slide, planned-stance height error, share of frames down, sinking and lift of one sole over a cycle of
    frames (K + 1, V, 3) (the last one period after the first) with the foot's planned stance (K + 1,);
    ``down`` (K,) marks the frames some sole vertex is down."""
    height, ground = _unrolled(frames, times, period, sole, speed, forward, up)
    k = len(height)
    down = height <= DOWN * leg_length  # (K, m)
    twice = np.concatenate([down, down])
    start = twice & ~np.concatenate([np.zeros((1, twice.shape[1]), bool), twice[:-1]])
    last = np.maximum.accumulate(np.where(start, np.arange(2 * k)[:, None], -1), axis=0)[k:]  # (K, m)
    cols = np.arange(height.shape[1])[None]
    drift = np.linalg.norm(ground[k:] - ground[np.maximum(last, 0), cols], axis=2)
    counted = down & (last >= 0)
    on = np.asarray(stance[:-1], bool)
    return {
        "slide": float(drift[counted].max()) if counted.any() else 0.0,
        "stance_height": float(np.abs(height[on]).max()) if on.any() else 0.0,
        "down_share": float(down.any(axis=1).mean()),
        "sink": float(max(0.0, -(height + sole.above[None]).min())),
        "lift": float(height.min(axis=1).max()),
        "vertices": int(len(sole.vertices)),
        "down": down.any(axis=1),
    }


def contact_report(frames: np.ndarray, cycle: Any, soles_: list[Sole]) -> dict[str, Any]:
    """Per-leg and worst figures (absolute and as shares of the leg length) of frames (K + 1, V, 3) sampled
    at the cycle's times (a :class:`pdeanim.cyclic.locomotion.GaitCycle`); JSON-able."""
    plan = cycle.plan
    unit_len = plan.leg_length
    legs = []
    for i, (leg, sole) in enumerate(zip(plan.legs, soles_, strict=True)):
        fig = foot_figures(frames, cycle.times, cycle.params.period, cycle.paths.stance[:, i], sole,
                           cycle.speed, plan.axes.forward, plan.axes.up, unit_len)
        fig.pop("down")
        legs.append({"leg": leg.name, **fig})
    worst = {k: max(x[k] for x in legs) for k in ("slide", "stance_height", "sink", "lift")}
    return {
        "legs": legs,
        "measured_on": "every mesh vertex a leg moves within 2% of the mesh height of the ground at rest, "
                       "in every frame it is within 1% of the leg of its rest height",
        "slide_max": worst["slide"], "slide_max_rel": worst["slide"] / unit_len,
        "stance_height_max": worst["stance_height"],
        "stance_height_max_rel": worst["stance_height"] / unit_len,
        "sink_max_rel": worst["sink"] / unit_len,
        "down_share_min": min(x["down_share"] for x in legs), "duty": cycle.duty,
        "leg_length": unit_len,
    }
