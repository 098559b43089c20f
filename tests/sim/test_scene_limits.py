"""Scene work bound shared by submission and simulation, list bounds, and the ignored legacy ``seed``."""

from __future__ import annotations

import re

import pytest

from pdeanim.errors import LimitError, ParameterError
from pdeanim.sim.scene import MAX_TET_SWEEPS, SceneParams


def test_work_bound_is_an_upper_bound_of_the_simulated_work():
    """With automatic substeps the bound uses max_substeps, and any substep count the simulator may choose
    (at most max_substeps) gives no more work: a scene accepted at submission is accepted by the simulator."""
    scene = SceneParams(frames=1000, max_substeps=400, target_tets=12_000)
    scene.check_work()
    assert all(scene.work(s) <= scene.work() for s in (1, 57, 400))
    # the defaults fit at the service's largest frame count
    assert SceneParams(frames=2000, target_tets=3000).work() <= MAX_TET_SWEEPS


def test_work_over_budget_names_what_to_lower():
    scene = SceneParams(frames=2000, substeps=400, iterations=50)
    with pytest.raises(LimitError, match="lower frames"):
        scene.check_work()


def test_region_counts_are_bounded():
    with pytest.raises(ParameterError, match="at most 256 pins"):
        SceneParams.from_dict({"pins": [{"box": [0, 0, 0, 1, 1, 1]}] * 257})


def test_seed_is_accepted_and_dropped():
    assert "seed" not in SceneParams.from_dict({"seed": 12}).to_dict()
    with pytest.raises(ParameterError, match="seed"):
        SceneParams.from_dict({"seed": "x"})


@pytest.mark.parametrize("params, field, bound", [
    ({"gravity": [1e308] * 3}, "gravity", "1e+06"), ({"gravity": [0, -2e6, 0]}, "gravity", "1e+06"),
    ({"young": 1e300}, "young", "1e+15"), ({"density": 1e300}, "density", "1e+09"),
    ({"damping": 1e300}, "damping", "1e+06")])
def test_forces_and_materials_are_bounded_naming_the_field_and_the_bound(params, field, bound):
    """Values past these bounds made the automatic stiffness and substeps overflow (ZeroDivisionError after
    three attempts of a job); they are refused when the scene is built, as at submission (422)."""
    with pytest.raises(ParameterError, match=rf"^{field} .*{re.escape(bound)}"):
        SceneParams.from_dict(params)
    ok = SceneParams.from_dict({"gravity": [0, -9810, 0], "young": 2e11, "density": 19_300, "damping": 50})
    assert ok.gravity == (0.0, -9810.0, 0.0)
