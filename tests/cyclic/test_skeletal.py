"""Walk and run cycles on a small skinned rig (Eq. 9-10 on the feet and the hip, two-bone IK legs)."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.cyclic.skeletal import StepParams, cycle_world_matrices, foot_and_hip_offsets, step_cycle
from pdeanim.errors import InputError, ParameterError
from pdeanim.gltf import skin

from .rig import JOINTS, rest_positions, rig_geometry, rig_glb


@pytest.fixture(scope="module")
def rig():
    return skin.load_skinned(rig_glb())


def test_rig_loads_at_rest(rig):
    assert rig.joint_names == [n for n, _, _ in JOINTS]
    rest = skin.skin_vertices(rig, skin.joint_world_matrices(rig))
    assert np.allclose(rest, rig_geometry()[0], atol=1e-6)


def test_literal_offsets_follow_equation_10():
    p = StepParams.preset("walk", literal=True, height_right=0.02, lift_right=0.01, length_left=0.05)
    t = np.linspace(0, 1, 9)
    right, left, _ = foot_and_hip_offsets(p, t, leg=2.0)
    ty, tz = np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)
    assert np.allclose(right[:, 1], 2.0 * (ty * (p.step_height + 0.02) + 0.01))
    assert np.allclose(right[:, 2], -2.0 * tz * p.step_length)
    assert np.allclose(left[:, 1], 2.0 * ty * p.step_height)
    assert np.allclose(left[:, 2], 2.0 * tz * (p.step_length + 0.05))


def test_feet_reach_their_targets_and_bones_keep_length(rig):
    p = StepParams.preset("walk")
    t = np.linspace(0, 1, 13)
    world = cycle_world_matrices(rig, p, t)
    pos = world[:, :, :3, 3]
    rest = rest_positions()
    leg = np.linalg.norm(rest[0] - rest[3])
    right, left, hip = foot_and_hip_offsets(p, t, leg)
    assert np.abs(pos[:, 6] - (rest[6] + right)).max() < 1e-9
    assert np.abs(pos[:, 3] - (rest[3] + left)).max() < 1e-9
    assert np.abs(pos[:, 0, [0, 2]] - (rest[0] + hip)[:, [0, 2]]).max() < 1e-12
    drop = (rest[0, 1] + hip[:, 1]) - pos[:, 0, 1]  # lowered only as far as the stride needs
    assert (drop >= 0).all() and drop.max() < 0.1 and drop[np.argmax(np.abs(right[:, 2]))] > 0
    for j, (_, parent, _) in enumerate(JOINTS):
        if parent >= 0:
            assert np.allclose(np.linalg.norm(pos[:, j] - pos[:, parent], axis=1),
                               np.linalg.norm(rest[j] - rest[parent]), atol=1e-9)
    assert (pos[:, [3, 6], 1] >= rest[[3, 6], 1] - 1e-12).all()  # stance feet stay on the ground
    assert np.allclose(world[:, [3, 6], :3, :3], np.eye(3), atol=1e-9)  # feet stay level
    knee_forward = pos[:, [2, 5], 2] - 0.5 * (pos[:, [1, 4], 2] + pos[:, [3, 6], 2])
    assert (knee_forward > 0).all()  # knees keep bending forward


@pytest.mark.parametrize("gait", ["walk", "run"])
def test_cycle_poses_loop(rig, gait):
    poses = step_cycle(rig, StepParams.preset(gait), frames=16)
    assert poses.vertices.shape == (17, len(rig.rest_vertices), 3)
    assert np.abs(poses.vertices[-1] - poses.vertices[0]).max() < 1e-5
    assert poses.times[-1] == pytest.approx(1 / StepParams.preset(gait).frequency)
    assert np.ptp(poses.vertices[:, :, 2], axis=0).max() > 0.1  # the feet do move


def test_bad_step_input(rig):
    with pytest.raises(ParameterError):
        StepParams.preset("skip")
    with pytest.raises(ParameterError):
        StepParams.preset("walk", frequency=0)
    with pytest.raises(ParameterError):
        StepParams.preset("walk", stride=1)
    with pytest.raises(InputError):
        cycle_world_matrices(rig, StepParams(), np.zeros(1), right_foot="toe")
    with pytest.raises(InputError):
        cycle_world_matrices(rig, StepParams(), np.zeros(1), hip="knee.L")
