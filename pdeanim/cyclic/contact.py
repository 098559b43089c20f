"""Measure how well feet stay planted: the sole of every foot (the lowest mesh vertices bound to the foot)
is followed through the cycle in the ground's frame (the clip's positions plus the root moved forward at the
travel speed). During each stance: slide (the largest horizontal drift from where the sole touched down) and
height error (off its rest height); over the cycle: the share of frames the sole is down and how far it
sinks below the ground."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

SOLE_WEIGHT = 0.5
"""A sole vertex has at least this skin weight on the foot's joints."""
SOLE_HEIGHT = 0.03
"""... and lies within this share of the leg length of the foot's lowest vertex at rest."""
DOWN = 0.01
"""A sole is down when within this share of the leg length of its rest height."""


@dataclass(frozen=True)
class Sole:
    """The vertex indices (m,) of one foot's sole and their rest positions (m, 3)."""

    vertices: np.ndarray
    rest: np.ndarray


def soles(skinned: Any, subtrees: np.ndarray, feet: list[int], leg_length: float,
          rest_vertices: np.ndarray) -> list[Sole]:
    """The sole of each foot joint: mesh vertices mostly bound to the foot (and joints under it), lowest at
    rest; a foot without such vertices is measured at its lowest bound vertex."""
    w = np.zeros((len(rest_vertices), len(feet)))
    for i, foot in enumerate(feet):
        on_foot = subtrees[foot][skinned.vertex_joints]  # (V, n) bool
        w[:, i] = (skinned.vertex_weights * on_foot).sum(axis=1)
    out = []
    for i in range(len(feet)):
        bound = np.flatnonzero(w[:, i] >= SOLE_WEIGHT)
        if not len(bound):
            bound = np.array([int(np.argmax(w[:, i]))])
        y = rest_vertices[bound, 1]
        keep = bound[y <= y.min() + SOLE_HEIGHT * leg_length]
        out.append(Sole(keep, rest_vertices[keep]))
    return out


def _runs(stance: np.ndarray) -> list[np.ndarray]:
    """Frame indices of each contiguous stance of a cyclic (K,) mask, in time order (wrapping runs joined)."""
    k = len(stance)
    if stance.all():
        return [np.arange(k)]
    start = int(np.argmin(stance))  # a swing frame: no run crosses it
    order = (start + np.arange(k)) % k
    s = stance[order]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], s.astype(int), [0]])))
    return [order[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True)]


def foot_figures(frames: np.ndarray, times: np.ndarray, period: float, stance: np.ndarray, sole: Sole,
                 speed: float, forward: np.ndarray, up: np.ndarray, leg_length: float) -> dict[str, float]:
    """Slide, stance height error, share of frames down, sinking and lift of one sole over a cycle of
    frames (K + 1, V, 3) (the last one period after the first) with the foot's stance mask (K + 1,)."""
    pts = frames[:-1][:, sole.vertices].astype(np.float64)  # (K, m, 3)
    t = np.asarray(times[:-1], np.float64)
    height = (pts - sole.rest[None]) @ up  # (K, m)
    slide = 0.0
    for run in _runs(np.asarray(stance[:-1], bool)):
        tr = t[run] + period * (np.cumsum(np.diff(t[run], prepend=t[run[0]]) < 0))
        ground = pts[run] + (speed * tr)[:, None, None] * forward
        drift = ground - ground[:1]
        drift = drift - (drift @ up)[..., None] * up
        slide = max(slide, float(np.linalg.norm(drift, axis=2).max()))
    on = stance[:-1]
    lowest = height.min(axis=1)
    return {
        "slide": slide,
        "stance_height": float(np.abs(height[on]).max()) if on.any() else 0.0,
        "down_share": float(np.mean(np.abs(lowest) <= DOWN * leg_length)),
        "sink": float(max(0.0, -lowest.min())),
        "lift": float(height.max()),
    }


def contact_report(frames: np.ndarray, cycle: Any, soles_: list[Sole]) -> dict[str, Any]:
    """Per-leg and worst figures (absolute and as shares of the leg length) of frames (K + 1, V, 3) sampled
    at the cycle's times (a :class:`pdeanim.cyclic.locomotion.GaitCycle`)."""
    plan = cycle.plan
    unit_len = plan.leg_length
    legs = []
    for i, (leg, sole) in enumerate(zip(plan.legs, soles_, strict=True)):
        fig = foot_figures(frames, cycle.times, cycle.params.period, cycle.paths.stance[:, i], sole,
                           cycle.speed, plan.axes.forward, plan.axes.up, unit_len)
        legs.append({"leg": leg.name, **fig})
    worst = {k: max(x[k] for x in legs) for k in ("slide", "stance_height", "sink", "lift")}
    return {
        "legs": legs,
        "slide_max": worst["slide"], "slide_max_rel": worst["slide"] / unit_len,
        "stance_height_max": worst["stance_height"],
        "stance_height_max_rel": worst["stance_height"] / unit_len,
        "sink_max_rel": worst["sink"] / unit_len,
        "down_share_min": min(x["down_share"] for x in legs), "duty": cycle.duty,
        "leg_length": unit_len,
    }
