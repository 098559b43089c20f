"""One locomotion cycle of a skinned character from its skeleton alone: foot paths (Eq. 9-10 with each
leg's phase), the body moving over them, leg IK onto the foot targets, feet kept level, and the mesh
skinned by linear blend skinning. The cycle repeats every 1 / f seconds; its travel speed is the speed a
game moves the root at so planted feet do not slide."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..poses import Poses, make_poses
from .bodymotion import leg_drops, move_body, row_heights, row_turns, spine_flex, sway
from .bodyplan import BodyPlan
from .footpaths import FootPaths, foot_paths, travel_speed
from .gaits import GaitParams, leg_phases
from .legik import rest_bends, solve_leg
from .roll import roll_of, rolled_targets
from .rotations import turn_subtree

CROUCH_STEPS = 6
"""Rounds of sinking rows until every leg reaches (a pitch couples the rows, so one round may not do)."""
MAX_MISS = 0.01
"""Largest IK miss allowed, as a share of the leg length, before the stride is called too long."""
MAX_FRAMES = 2_000
"""Most frames one cycle may have."""


@dataclass(frozen=True)
class GaitCycle:
    """A solved cycle: times (K,) seconds, world (K, J, 4, 4) joint matrices, the foot paths, targets
    (K, n, 3), phases (n,), duty, speed (units per second along plan.axes.forward), pitch (K,) radians and
    the IK miss (K, n) of every foot."""

    plan: BodyPlan
    params: GaitParams
    times: np.ndarray
    world: np.ndarray
    paths: FootPaths
    targets: np.ndarray
    phases: np.ndarray
    duty: float
    speed: float
    pitch: np.ndarray
    miss: np.ndarray

    def metadata(self) -> dict[str, Any]:
        """JSON-able gait and travel description (what a game needs to move the root)."""
        names = self.plan.skeleton.names
        period = self.params.period
        return {
            "gait": {"name": self.params.gait, "duty": self.duty, "frequency": self.params.frequency,
                     "period_s": period,
                     "legs": [{"name": leg.name, "foot": names[leg.foot], "phase": float(p)}
                              for leg, p in zip(self.plan.legs, self.phases, strict=True)]},
            "travel": {"speed": self.speed, "direction": self.plan.axes.forward.tolist(),
                       "distance_per_cycle": self.speed * period, "period_s": period},
        }


def _fallback_bends(plan: BodyPlan) -> list[np.ndarray]:
    """Bend direction of a leg that is straight at rest: elbows of front rows point back, knees forward."""
    f = plan.axes.forward
    return [-f if plan.rows > 1 and leg.row == 0 else f for leg in plan.legs]


def _settle(plan: BodyPlan, params: GaitParams, paths: FootPaths, targets: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The body moved over the feet (world matrices (K, J, 4, 4) before IK, and its pitch (K,)): rows sink
    until every leg reaches its foot target, then every row sinks to the lowest row's mean height (no lasting
    pitch) and sinks again where that made a leg overreach."""
    heights, turns = row_heights(plan, params, paths), row_turns(plan, params, paths)
    side, flex = sway(plan, params, paths), spine_flex(plan, params, paths)
    for round_ in range(2):
        for _ in range(CROUCH_STEPS):
            world, pitch = move_body(plan, params, heights, turns, side, flex)
            drop = leg_drops(plan, world, targets)
            if drop.max() <= 1e-9 * plan.leg_length:
                break
            heights = heights - drop
        if round_ == 0:
            level = heights.mean(axis=0)
            heights = heights - (level - level.min())
    return move_body(plan, params, heights, turns, side, flex)


def solve_cycle(plan: BodyPlan, params: GaitParams, times: np.ndarray) -> GaitCycle:
    """Joint world matrices of the cycle at times (K,) seconds. Raises ParameterError when the gait does not
    fit the legs or the stride is longer than the legs reach."""
    sk, legs = plan.skeleton, plan.legs
    phases, duty = leg_phases(params.gait, list(legs), params.duty)
    sides = np.array([leg.side for leg in legs])
    unit_len = plan.leg_length
    paths = foot_paths(params, times, phases, duty, sides, plan.axes.up, plan.axes.forward, unit_len)
    feet = [leg.foot for leg in legs]
    targets = sk.positions[feet][None] + paths.offset
    turns = {}
    for i, leg in enumerate(legs):  # plantigrade feet roll: heel strike, flat, push-off about the ball
        if leg.toe >= 0:
            pitch_i, blend = roll_of(params, times, float(phases[i]), duty)
            targets[:, i], turns[i] = rolled_targets(sk, leg.foot, leg.toe, targets[:, i], pitch_i, blend,
                                                     plan.axes.left, plan.axes.forward)
    world, pitch = _settle(plan, params, paths, targets)
    for i, (leg, target, fallback) in enumerate(zip(legs, np.moveaxis(targets, 1, 0), _fallback_bends(plan),
                                                    strict=True)):
        bends = rest_bends(sk.positions[list(leg.ik)]) if len(leg.ik) == 4 else None
        solve_leg(world, sk.subtrees, leg.ik, target, bends, fallback)
        level = sk.rest[leg.foot, :3, :3] @ np.linalg.inv(world[:, leg.foot, :3, :3])
        if i in turns:
            level = turns[i] @ level
        turn_subtree(world, sk.subtrees[leg.foot], level, world[:, leg.foot, :3, 3].copy())
        if i in turns:  # toes stay flat while the heel is up
            flat = np.linalg.inv(turns[i]) @ np.eye(3)
            heel_up = (turns[i] @ plan.axes.forward) @ plan.axes.up < 0
            back = np.where(heel_up[:, None, None], flat, np.eye(3))
            turn_subtree(world, sk.subtrees[leg.toe], back, world[:, leg.toe, :3, 3].copy())
    miss = np.linalg.norm(world[:, feet][..., :3, 3] - targets, axis=2)
    worst = miss.max(axis=0) / np.array([leg.length for leg in legs])
    if worst.max() > MAX_MISS:
        bad = legs[int(np.argmax(worst))]
        raise ParameterError(
            f"the {bad.name} leg misses its foot target by {worst.max():.1%} of its length: the stride is "
            f"longer than the legs reach (step_length {params.step_length}, "
            f"step_height {params.step_height})")
    speed = travel_speed(params, duty, unit_len)
    return GaitCycle(plan, params, np.asarray(times, np.float64), world, paths, targets, phases, duty,
                     speed, pitch, miss)


def cycle_times(params: GaitParams, frames: int) -> np.ndarray:
    """frames + 1 times (seconds) over one period; the last equals the first one cycle later."""
    if not 2 <= int(frames) <= MAX_FRAMES:
        raise ParameterError(f"frames must be in 2..{MAX_FRAMES}, got {frames}")
    return np.arange(int(frames) + 1) / (int(frames) * params.frequency)


def cycle_poses(skinned: Any, cycle: GaitCycle) -> Poses:
    """The skinned mesh's vertices over the cycle as Poses (the last frame repeats the first)."""
    from ..gltf.skin import skin_vertices

    verts = skin_vertices(skinned, cycle.world)
    if abs(cycle.times[-1] - cycle.times[0] - cycle.params.period) <= 1e-9 * cycle.params.period:
        verts[-1] = verts[0]  # one period later: the cycle's start, exactly
    meta = {"producer": "cyclic-gait", **cycle.params.to_dict(), **cycle.metadata()}
    return make_poses(verts, skinned.faces, cycle.times, meta=meta)
