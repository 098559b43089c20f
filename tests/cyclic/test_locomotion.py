"""Locomotion cycles on skinned biped, quadruped and hexapod rigs: every gait loops exactly, planted feet
stay on the ground and still (in the ground's frame, the root moving at the travel speed), every leg steps
with its gait's phase, the IK reaches its targets, three-bone legs keep their bend ratio, and the body bobs,
pitches and counter-turns.

Tolerances: the rigs' feet are rigid pads, so the generator's own error is float32 rounding of the skinned
vertices (measured slide <= 5e-8 of the leg length); planted feet must stay within 1e-6 of the leg length in
height and slide, 100x that.
"""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.cyclic.bodyplan import plan_of
from pdeanim.cyclic.contact import contact_report, soles
from pdeanim.cyclic.gaits import GaitParams
from pdeanim.cyclic.legik import rest_bends
from pdeanim.cyclic.locomotion import cycle_poses, cycle_times, solve_cycle
from pdeanim.errors import ParameterError
from pdeanim.gltf.skin import load_skinned, skin_vertices

from .rig import BIPED, HEXAPOD, QUADRUPED, rig_glb

RIGS = {"biped": BIPED, "quadruped": QUADRUPED, "hexapod": HEXAPOD}
CASES = [("biped", "walk"), ("biped", "run"), ("quadruped", "walk"), ("quadruped", "trot"),
         ("quadruped", "pace"), ("quadruped", "canter"), ("quadruped", "gallop"), ("hexapod", "tripod"),
         ("hexapod", "wave")]
FRAMES = 40
PLANTED = 1e-6  # of the leg length


@pytest.fixture(scope="module")
def rigs():
    out = {}
    for name, rig in RIGS.items():
        skinned = load_skinned(rig_glb(rig))
        out[name] = (skinned, plan_of(skinned))
    return out


@pytest.fixture(scope="module")
def cycles(rigs):
    out = {}
    for rig, gait in CASES:
        skinned, plan = rigs[rig]
        params = GaitParams.preset(gait)
        cycle = solve_cycle(plan, params, cycle_times(params, FRAMES))
        out[rig, gait] = (skinned, cycle, cycle_poses(skinned, cycle))
    return out


@pytest.mark.parametrize(("rig", "gait"), CASES)
def test_loop_closes_exactly(cycles, rig, gait):
    skinned, cycle, poses = cycles[rig, gait]
    assert np.array_equal(poses.vertices[-1], poses.vertices[0])
    later = solve_cycle(cycle.plan, cycle.params, cycle.times + cycle.params.period)  # the next cycle
    assert np.abs(later.world - cycle.world).max() < 1e-9 * cycle.plan.leg_length
    assert poses.times[-1] == pytest.approx(cycle.params.period)


@pytest.mark.parametrize(("rig", "gait"), CASES)
def test_planted_feet_stay_on_the_ground(cycles, rig, gait):
    skinned, cycle, poses = cycles[rig, gait]
    plan = cycle.plan
    rest = skin_vertices(skinned, plan.skeleton.rest)
    feet = soles(skinned, plan, rest)
    assert all(len(s.vertices) == 4 for s in feet)  # every vertex near the ground: the pads' undersides
    report = contact_report(poses.vertices, cycle, feet)
    assert report["slide_max_rel"] < PLANTED and report["stance_height_max_rel"] < PLANTED
    assert report["sink_max_rel"] < PLANTED
    for leg in report["legs"]:  # down for the stance (plus a frame where a lift or landing is slow)
        assert cycle.duty - 1.0 / FRAMES <= leg["down_share"] <= cycle.duty + 2.5 / FRAMES
        assert leg["lift"] > 0.5 * cycle.params.step_height * plan.leg_length


@pytest.mark.parametrize(("rig", "gait"), CASES)
def test_every_leg_steps_with_its_phase(cycles, rig, gait):
    skinned, cycle, poses = cycles[rig, gait]
    plan, sk = cycle.plan, cycle.plan.skeleton
    foot = cycle.world[:-1][:, [leg.foot for leg in plan.legs]][..., :3, 3]  # (K, n, 3)
    lifted = (foot - sk.positions[[leg.foot for leg in plan.legs]]) @ plan.axes.up > 1e-9 * plan.leg_length
    for i, phase in enumerate(cycle.phases):
        landing = np.flatnonzero(lifted[:, i] & ~np.roll(lifted[:, i], -1))  # last airborne frame
        assert len(landing) == 1
        measured = ((landing[0] + 1) / FRAMES) % 1.0
        assert min(abs(measured - phase), 1 - abs(measured - phase)) <= 1.0 / FRAMES + 1e-9
        share = 1.0 - lifted[:, i].mean()
        assert abs(share - cycle.duty) <= 1.0 / FRAMES + 1e-9


@pytest.mark.parametrize(("rig", "gait"), CASES)
def test_ik_reaches_and_bones_keep_their_length(cycles, rig, gait):
    skinned, cycle, poses = cycles[rig, gait]
    sk = cycle.plan.skeleton
    assert cycle.miss.max() < 1e-9 * cycle.plan.leg_length
    pos = cycle.world[..., :3, 3]
    has_parent = sk.parents >= 0
    length = np.linalg.norm(pos[:, has_parent] - pos[:, sk.parents[has_parent]], axis=2)
    rest = np.linalg.norm(sk.positions[has_parent] - sk.positions[sk.parents[has_parent]], axis=1)
    assert np.abs(length - rest).max() < 1e-9
    for leg in cycle.plan.legs:  # feet level: the rest orientation all the time
        assert np.abs(cycle.world[:, leg.foot, :3, :3] - sk.rest[leg.foot, :3, :3]).max() < 1e-9


def test_three_bone_legs_keep_their_bend_ratio(cycles):
    for gait in ("walk", "gallop"):
        _, cycle, _ = cycles["quadruped", gait]
        for leg in cycle.plan.legs:
            if len(leg.ik) != 4:
                continue
            b1, b2 = rest_bends(cycle.plan.skeleton.positions[list(leg.ik)])
            bends = np.array([rest_bends(cycle.world[k, list(leg.ik), :3, 3]) for k in range(FRAMES)])
            assert np.allclose(bends[:, 1] / bends[:, 0], b2 / b1, atol=1e-6)
            assert np.ptp(bends[:, 0]) > 0.1  # the legs do bend and stretch


def test_body_bobs_pitches_and_counter_turns(cycles):
    _, gallop, _ = cycles["quadruped", "gallop"]
    assert np.degrees(np.ptp(gallop.pitch)) > 2.0 and abs(np.mean(gallop.pitch)) < np.ptp(gallop.pitch) / 2
    _, trot, _ = cycles["quadruped", "trot"]
    sk, plan = trot.plan.skeleton, trot.plan

    def yaw(j: int) -> np.ndarray:  # turn of joint j's frame about the up axis, from rest
        f = np.einsum("kij,j->ki", trot.world[:, j, :3, :3] @ sk.rest[j, :3, :3].T, plan.axes.forward)
        return np.arctan2(f @ plan.axes.left, f @ plan.axes.forward)

    chest, head, tail = yaw(plan.spine[-1]), yaw(plan.neck[-1]), yaw(plan.tail[-1])
    assert np.ptp(chest) > 0.05 and np.abs(head).max() < 0.1 * np.abs(chest).max()  # the head looks ahead
    hips = yaw(plan.root)
    assert np.corrcoef(hips, tail)[0, 1] < -0.9  # the tail sways against the hips
    assert np.corrcoef(hips, chest)[0, 1] < -0.9  # trot: diagonal legs turn hips and shoulders apart
    height = trot.world[:, plan.root, 1, 3] - sk.positions[plan.root, 1]
    assert (height <= 1e-12).all() and np.ptp(height) > 0.01 * plan.leg_length


def test_a_gallop_arches_the_back_and_keeps_the_head_level(cycles):
    _, gallop, _ = cycles["quadruped", "gallop"]
    sk, plan = gallop.plan.skeleton, gallop.plan

    def pitch(j: int) -> np.ndarray:  # nose-up turn of joint j's frame about the lateral axis, from rest
        f = np.einsum("kij,j->ki", gallop.world[:, j, :3, :3] @ sk.rest[j, :3, :3].T, plan.axes.forward)
        return np.arctan2(f @ plan.axes.up, f @ plan.axes.forward)

    arch = pitch(plan.root) - pitch(plan.spine[-1])  # the chest dips against the hips when gathered
    assert np.ptp(arch) > 0.2 and np.corrcoef(arch, gallop.paths.forward[:, 2:].mean(axis=1))[0, 1] > 0.9
    assert np.abs(pitch(plan.neck[-1])).max() < 0.2 * np.abs(pitch(plan.spine[-1])).max()


def test_a_stride_longer_than_the_legs_is_refused(rigs):
    _, plan = rigs["quadruped"]
    params = GaitParams.preset("trot", step_length=1.5)
    with pytest.raises(ParameterError, match="stride is longer than the legs reach"):
        solve_cycle(plan, params, cycle_times(params, 8))
    with pytest.raises(ParameterError, match="frames must be in"):
        cycle_times(params, 1)
