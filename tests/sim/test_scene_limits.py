"""Scene work bound shared by submission and simulation, list bounds, and the ignored legacy ``seed``."""

from __future__ import annotations

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
