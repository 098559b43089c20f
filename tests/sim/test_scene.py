"""SceneParams: defaults, round trip, and a ParameterError for every unknown key or bad value."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.errors import ParameterError
from pdeanim.sim.scene import SceneParams

DRIVER = {"region": {"box": [0, 0, 0, 1, 1, 1], "relative": True},
          "keyframes": [{"t": 0.5, "rotate": [0, 1, 0, 45]}, {"t": 1.0, "translate": [0, 1, 0]}]}


def test_round_trip_and_defaults():
    scene = SceneParams.from_dict({"frames": 12, "gravity": [0, 0, -9.81], "pins": [{"indices": [1, 2]}],
                                   "drivers": [DRIVER], "ground": {"point": [0, 0, -1], "normal": [0, 0, 1]}})
    again = SceneParams.from_dict(scene.to_dict())
    assert again == scene and again.gravity == (0.0, 0.0, -9.81)
    assert SceneParams().frames == 100 and SceneParams().substeps is None
    np.testing.assert_allclose(SceneParams(frames=4, fps=10).frame_times(), [0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(SceneParams(frames=5, duration=2.0).frame_times(), [0, 0.5, 1, 1.5, 2])


@pytest.mark.parametrize("bad", [
    {"framez": 10},
    {"frames": 0},
    {"frames": 2.5},
    {"fps": -1},
    {"gravity": [0, 1]},
    {"gravity": [0, float("nan"), 0]},
    {"young": 0},
    {"poisson": 0.5},
    {"density": -3},
    {"damping": -1},
    {"target_tets": 10},
    {"substeps": 0},
    {"iterations": 0},
    {"pins": [{"box": [1, 0, 0, 0, 1, 1]}]},
    {"pins": [{"plane": [0, 0, 0, 0, 0, 0]}]},
    {"pins": [{"indices": []}]},
    {"pins": [{"box": [0, 0, 0, 1, 1, 1], "sphere": 1}]},
    {"drivers": [{"region": {"indices": [0]}}]},
    {"drivers": [{**DRIVER, "keyframes": [{"t": 0.8}, {"t": 0.2}]}]},
    {"drivers": [{**DRIVER, "keyframes": [{"t": 1.5}]}]},
    {"drivers": [{**DRIVER, "keyframes": [{"t": 1.0, "rotate": [0, 0, 0, 90]}]}]},
    {"ground": {"normal": [0, 0, 0]}},
    {"ground": {"friction": 2}},
])
def test_bad_parameters_are_rejected(bad):
    with pytest.raises(ParameterError):
        SceneParams.from_dict(bad)
