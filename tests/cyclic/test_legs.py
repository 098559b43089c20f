"""Legs, sides, rows and the axial chains found from skeletons alone (test rigs and the public Fox)."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.cyclic.bodyplan import plan_of
from pdeanim.errors import InputError, MeshInputError
from pdeanim.gltf.skin import load_skinned

from .rig import BIPED, HEXAPOD, QUADRUPED, Rig, rig_glb


def _plan(rig: Rig, **kw):
    return plan_of(load_skinned(rig_glb(rig)), **kw)


def _legs(plan) -> dict[str, tuple[str, int]]:
    names = plan.skeleton.names
    return {leg.name: (names[leg.foot], len(leg.ik) - 1) for leg in plan.legs}


@pytest.mark.parametrize("neutral", [False, True])
def test_quadruped_legs_rows_and_chains(neutral):
    rig = QUADRUPED.renamed() if neutral else QUADRUPED
    plan = _plan(rig)
    n = {a: b for (a, _, _), (b, _, _) in zip(QUADRUPED.joints, rig.joints, strict=True)}
    assert _legs(plan) == {"front-left": (n["front.L.2"], 2), "front-right": (n["front.R.2"], 2),
                           "hind-left": (n["hind.L.3"], 3), "hind-right": (n["hind.R.3"], 3)}
    assert np.allclose(plan.axes.forward, [0, 0, 1]) and np.allclose(plan.axes.left, [1, 0, 0])
    sk = plan.skeleton
    assert sk.names[plan.root] == n["pelvis"] and sk.names[plan.pivot] == n["pelvis"]
    assert [sk.names[j] for j in plan.spine] == [n["spine"], n["chest"]]
    assert [sk.names[j] for j in plan.neck] == [n["neck"], n["head"]]
    assert [sk.names[j] for j in plan.tail] == [n["tail.0"], n["tail.1"]]


def test_hexapod_and_biped_legs():
    hexa = _plan(HEXAPOD.renamed())
    assert [leg.name for leg in hexa.legs] == ["front-left", "front-right", "middle-left", "middle-right",
                                               "hind-left", "hind-right"]
    assert all(len(leg.ik) == 3 for leg in hexa.legs) and hexa.rows == 3
    biped = _plan(BIPED)
    assert _legs(biped) == {"left": ("foot.L", 2), "right": ("foot.R", 2)}
    assert biped.rows == 1 and not biped.spine and biped.skeleton.names[biped.root] == "hip"


@pytest.mark.parametrize("degrees", [90.0, -135.0])
def test_a_turned_rig_faces_where_its_head_is(degrees):
    plan = _plan(QUADRUPED.turned(degrees).renamed())
    a = np.radians(degrees)
    assert np.allclose(plan.axes.forward, [np.sin(a), 0.0, np.cos(a)], atol=1e-9)
    assert [leg.name for leg in plan.legs][:2] == ["front-left", "front-right"]
    assert {leg.side for leg in plan.legs} == {-1, 1}


def test_the_public_fox_has_four_legs(data_dir):
    plan = plan_of(load_skinned(data_dir / "Fox.glb"))
    assert _legs(plan) == {"front-left": ("b_LeftHand_011", 2), "front-right": ("b_RightHand_08", 2),
                           "hind-left": ("b_LeftFoot02_018", 3), "hind-right": ("b_RightFoot02_022", 3)}
    names = plan.skeleton.names
    assert [names[j] for j in plan.neck] == ["b_Neck_04", "b_Head_05"]
    assert names[plan.tail[0]] == "b_Tail01_012" and np.allclose(plan.axes.forward, [0, 0, 1])


def test_legs_named_forward_given_and_body_joint():
    plan = _plan(QUADRUPED, legs=["hind.L.1:hind.L.3", "hind.R.3"], forward=[0, 0, -1])
    names = plan.skeleton.names
    assert [leg.name for leg in plan.legs] == ["left", "right"]
    by_name = {names[leg.foot]: leg for leg in plan.legs}
    assert names[by_name["hind.L.3"].chain[0]] == "hind.L.1" and len(by_name["hind.L.3"].ik) == 3
    assert names[by_name["hind.R.3"].chain[0]] == "hind.R.0"
    assert np.allclose(plan.axes.forward, [0, 0, -1])
    assert by_name["hind.L.3"].side == -1  # facing -z: +x is the right side
    assert names[_plan(QUADRUPED, root="pelvis").root] == "pelvis"
    with pytest.raises(InputError, match="ancestor of every leg"):
        _plan(QUADRUPED, root="chest")
    with pytest.raises(MeshInputError, match="no joint named 'toe'"):
        _plan(QUADRUPED, legs=["toe"])


def test_no_legs_names_the_joints_seen():
    snake = Rig([("s0", -1, (0.0, 0.2, 0.0)), ("s1", 0, (0.0, 0.0, 0.4)), ("s2", 1, (0.0, 0.0, 0.4))], ())
    with pytest.raises(InputError, match=r"no legs found.*s0 .*s1 .*s2 .*--legs"):
        _plan(snake)
