"""The body's motion under the feet: each row of legs sets a height (a bob that follows its feet through
stance) and a turn (its girdle turns with the stride of its feet); the body rises, pitches and turns about
the hind girdle to follow the rows, the spine bends sideways between the girdles (and arches as the feet
gather under the body in a canter or gallop), the neck undoes the turn and pitch
so the head keeps looking ahead (on two legs the chest turns against the hips), and the tail sways against
the hips. A row sinks further where its legs could not reach their feet (a long stride needs bent knees)."""

from __future__ import annotations

import numpy as np

from .bodyplan import BodyPlan
from .footpaths import FootPaths
from .gaits import BOUNCING, GaitParams
from .rotations import axis_angle, shift_subtree, turn_subtree

CHEST_COUNTER = 0.5
"""On two legs the chest turns against the hips by this share of their turn."""
REACH = 0.99
"""Legs reach at most this share of their length (never quite straight)."""


def _rows(plan: BodyPlan) -> list[np.ndarray]:
    return [np.array([i for i, leg in enumerate(plan.legs) if leg.row == r]) for r in range(plan.rows)]


def row_heights(plan: BodyPlan, params: GaitParams, paths: FootPaths) -> np.ndarray:
    """Heights (K, R) of each row's girdle from its bob: bouncing gaits sink at mid-stance, the others are
    highest there; never above rest (a straight leg could not follow)."""
    bob = params.hip_bob * plan.leg_length
    out = []
    for idx in _rows(plan):
        m = paths.bump[:, idx].mean(axis=1)
        out.append(-bob * m if params.gait in BOUNCING else bob * (m - m.max()))
    return np.stack(out, axis=1)


def row_turns(plan: BodyPlan, params: GaitParams, paths: FootPaths) -> np.ndarray:
    """Turn (K, R) in radians of each row's girdle about the up axis: the hip of the forward foot leads."""
    stride = max(2.0 * params.step_length * plan.leg_length, 1e-300)
    sides = np.array([leg.side for leg in plan.legs], np.float64)
    return np.stack([-params.spine_yaw * (paths.forward[:, idx] * sides[idx]).sum(axis=1) / stride
                     for idx in _rows(plan)], axis=1)


def spine_flex(plan: BodyPlan, params: GaitParams, paths: FootPaths) -> np.ndarray:
    """Arch (K,) in radians of the back: it flexes as the hind feet reach forward and the fore feet back
    (gathered), and extends the other way (stretched); zero on one row of legs."""
    rows = _rows(plan)
    if len(rows) < 2 or not params.spine_flex:
        return np.zeros(len(paths.forward))
    stride = max(2.0 * params.step_length * plan.leg_length, 1e-300)
    gather = paths.forward[:, rows[-1]].mean(axis=1) - paths.forward[:, rows[0]].mean(axis=1)
    return params.spine_flex * gather / stride


def sway(plan: BodyPlan, params: GaitParams, paths: FootPaths) -> np.ndarray:
    """Sideways shift (K,) toward the feet in stance."""
    sides = np.array([leg.side for leg in plan.legs], np.float64)
    return params.hip_sway * plan.leg_length * (paths.bump * sides).sum(axis=1) / plan.rows


def _pitch_line(plan: BodyPlan, params: GaitParams, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Height (K,) at the pivot and nose-up pitch (K,) of the line through the rows' heights."""
    if plan.rows == 1:
        return heights[:, 0], np.zeros(len(heights))
    p = plan.skeleton.positions
    x = (p[list(plan.girdles)] - p[plan.pivot]) @ plan.axes.forward
    xc = x - x.mean()
    slope = params.body_pitch * (heights - heights.mean(axis=1, keepdims=True)) @ xc / max(xc @ xc, 1e-300)
    return heights.mean(axis=1) - slope * x.mean(), np.arctan(slope)


def _turn_chain(world: np.ndarray, plan: BodyPlan, chain: tuple[int, ...], axis: np.ndarray,
                total: np.ndarray) -> None:
    """Spread a turn total (K,) about axis (K, 3) or (3,) over the joints of chain, each about itself."""
    sub = plan.skeleton.subtrees
    for j in chain:
        turn_subtree(world, sub[j], axis_angle(axis, total / len(chain)), world[:, j, :3, 3].copy())


def move_body(plan: BodyPlan, params: GaitParams, heights: np.ndarray, turns: np.ndarray,
              side: np.ndarray, flex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World matrices (K, J, 4, 4) with the body moved (legs not yet solved) and the body pitch (K,)."""
    sk, ax = plan.skeleton, plan.axes
    k = len(heights)
    world = np.broadcast_to(sk.rest, (k, *sk.rest.shape)).copy()
    lift, pitch = _pitch_line(plan, params, heights)
    hips, chest = turns[:, -1], turns[:, 0]
    pivot = sk.positions[plan.pivot]
    body = axis_angle(ax.up, hips) @ axis_angle(-ax.left, pitch)
    turn_subtree(world, sk.subtrees[plan.root], body, pivot)
    shift_subtree(world, sk.subtrees[plan.root], np.outer(lift, ax.up) + np.outer(side, ax.left))
    if plan.rows == 1:
        chest = -CHEST_COUNTER * hips
    if plan.spine:
        _turn_chain(world, plan, plan.spine, ax.up, chest - hips)
        bent = np.einsum("kij,j->ki", axis_angle(ax.up, chest), ax.left)
        _turn_chain(world, plan, plan.spine, bent, flex)
    if plan.neck:
        _turn_chain(world, plan, plan.neck, ax.up, -params.head_level * chest)
        lateral = np.einsum("kij,j->ki", axis_angle(ax.up, chest * (1 - params.head_level)), ax.left)
        _turn_chain(world, plan, plan.neck, lateral, params.head_level * (pitch - flex * bool(plan.spine)))
    if plan.tail:
        _turn_chain(world, plan, plan.tail, ax.up, -params.tail_sway * hips)
    return world, pitch


def leg_drops(plan: BodyPlan, world: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """How far (K, R) each row must sink so all its legs reach their foot targets (K, n, 3)."""
    up = plan.axes.up
    drops = np.zeros((len(world), plan.rows))
    for i, leg in enumerate(plan.legs):
        d = targets[:, i] - world[:, leg.ik[0], :3, 3]
        v = d @ up
        flat = np.einsum("ki,ki->k", d, d) - v * v
        need = -v - np.sqrt(np.maximum((REACH * leg.length) ** 2 - flat, 0.0))
        drops[:, leg.row] = np.maximum(drops[:, leg.row], need)
    return drops
