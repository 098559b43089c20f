"""Gait tables (footfall phases and duty factors per leg) and the Eq. 9-10 foot paths."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pdeanim.cyclic.bodyplan import plan_of
from pdeanim.cyclic.footpaths import LIFT, eq9_angle, foot_paths, swing_forward, travel_speed
from pdeanim.cyclic.gaits import GaitParams, leg_phases
from pdeanim.errors import ParameterError
from pdeanim.gltf.skin import load_skinned

from .rig import BIPED, HEXAPOD, QUADRUPED, rig_glb

PLANS = {name: plan_of(load_skinned(rig_glb(rig))) for name, rig in
         (("biped", BIPED), ("quadruped", QUADRUPED), ("hexapod", HEXAPOD))}


def _phases(rig: str, gait: str) -> tuple[dict[str, float], float]:
    plan = PLANS[rig]
    phases, duty = leg_phases(gait, list(plan.legs))
    return {leg.name: float(p) for leg, p in zip(plan.legs, phases, strict=True)}, duty


def test_quadruped_gaits():
    walk, duty = _phases("quadruped", "walk")
    assert duty == 0.75
    assert walk == {"hind-left": 0.0, "front-left": 0.25, "hind-right": 0.5, "front-right": 0.75}
    trot, duty = _phases("quadruped", "trot")
    assert duty == 0.5
    assert trot["front-left"] == trot["hind-right"] != trot["front-right"] == trot["hind-left"]
    pace, _ = _phases("quadruped", "pace")
    assert pace["front-left"] == pace["hind-left"] != pace["front-right"] == pace["hind-right"]
    canter, _ = _phases("quadruped", "canter")
    assert canter["hind-left"] == canter["front-right"] and len(set(canter.values())) == 3  # three beats
    gallop, duty = _phases("quadruped", "gallop")
    assert len(set(gallop.values())) == 4 and duty < 0.5  # four beats with a flight


def test_six_legs_tripod_and_wave():
    tripod, duty = _phases("hexapod", "tripod")
    assert duty == 0.5
    assert tripod["front-left"] == tripod["middle-right"] == tripod["hind-left"] == 0.0
    assert tripod["front-right"] == tripod["middle-left"] == tripod["hind-right"] == 0.5
    wave, duty = _phases("hexapod", "wave")
    assert duty == pytest.approx(5 / 6) and sorted(wave.values()) == pytest.approx(np.arange(6) / 6)
    assert wave["hind-left"] < wave["middle-left"] < wave["front-left"]  # back to front on each side


def test_two_legs_alternate():
    for gait in ("walk", "run"):
        phases, duty = _phases("biped", gait)
        assert abs(phases["left"] - phases["right"]) == 0.5 and duty == (0.6 if gait == "walk" else 0.4)


@pytest.mark.parametrize(("rig", "gait"), [("hexapod", "trot"), ("quadruped", "tripod"), ("quadruped", "run"),
                                           ("biped", "gallop"), ("biped", "wave")])
def test_a_gait_that_does_not_fit_the_legs_is_refused(rig, gait):
    with pytest.raises(ParameterError, match=f"the {gait} gait needs .* found"):
        leg_phases(gait, list(PLANS[rig].legs))


def test_bad_parameters():
    with pytest.raises(ParameterError, match="unknown gait"):
        GaitParams.preset("skip")
    with pytest.raises(ParameterError, match="stride"):
        GaitParams.preset("walk", stride=1)
    for bad in ({"frequency": 0}, {"duty": 1.0}, {"step_length": float("nan")}, {"literal": "maybe"},
                {"step_height": -1}):
        with pytest.raises(ParameterError):
            GaitParams.preset("trot", **bad)
    assert GaitParams.preset("walk", literal="true", duty="0.7").duty == 0.7


@given(u=st.lists(st.floats(0, 0.999), min_size=1, max_size=20), duty=st.floats(0.1, 0.9),
       height=st.floats(0.05, 0.4))
def test_stance_is_linear_and_swing_leaves_the_ground_straight_up(u, duty, height):
    u = np.asarray(u)[None]
    z = -np.cos(eq9_angle(u, duty))
    stance = u < duty
    assert np.allclose(z[stance], (1 - 2 * u / duty)[stance], atol=1e-9)  # constant backward speed
    swing = swing_forward(u, duty, np.array([height]), np.array([1.0]))
    w = (u - duty) / (1 - duty)
    back = 2 * (1 - duty) / duty  # the body's travel over the swing, in step lengths
    low = ~stance & (height * np.sin(np.pi * w) < LIFT)  # within LIFT of the ground: still in its frame
    ground = swing + back * w
    assert np.allclose(ground[low & (w < 0.5)], -1.0, atol=1e-12)
    assert np.allclose(ground[low & (w > 0.5)], 1.0 + back, atol=1e-12)
    ends = swing_forward(np.array([[duty, 1.0]]), duty, np.array([height]), np.array([1.0]))
    assert np.allclose(ends, [[-1.0, 1.0]])  # it joins the stance at lift-off and touch-down


def test_literal_paths_follow_equation_10():
    p = GaitParams.preset("walk", literal=True, height_right=0.02, lift_right=0.01, length_left=0.05)
    t = np.linspace(0, 1, 9)
    paths = foot_paths(p, t, np.array([0.0, 0.5]), 0.5, np.array([1, -1]), np.array([0.0, 1, 0]),
                       np.array([0.0, 0, 1]), 2.0)
    ty, tz = np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)
    left, right = paths.offset[:, 0], paths.offset[:, 1]
    assert np.allclose(right[:, 1], 2.0 * (ty * (p.step_height + 0.02) + 0.01))
    assert np.allclose(right[:, 2], -2.0 * tz * p.step_length)
    assert np.allclose(left[:, 1], 2.0 * ty * p.step_height)
    assert np.allclose(left[:, 2], 2.0 * tz * (p.step_length + 0.05))


def test_travel_speed_moves_the_ground_with_the_stance_foot():
    p = GaitParams.preset("trot")
    t = np.linspace(0, p.period, 200, endpoint=False)
    up, forward = np.array([0.0, 1, 0]), np.array([0.0, 0, 1])
    paths = foot_paths(p, t, np.array([0.0]), 0.5, np.array([1]), up, forward, 1.5)
    speed = travel_speed(p, 0.5, 1.5)
    ground = paths.offset[:, 0, 2] + speed * t
    assert np.ptp(ground[paths.stance[:, 0]]) < 1e-12 and speed == pytest.approx(2 * 0.3 * 1.5 * 1.8 / 0.5)
