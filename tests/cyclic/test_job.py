"""Cyclic job options and the whole pipeline on the generated meshes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pdeanim.clip import load_clip
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.errors import InputError, MeshInputError, ParameterError


def test_options_round_trip_and_flat_overrides():
    opts = CyclicOptions.from_dict({"mode": "dolphin", "amplitude": 0.05, "n_curves": 25,
                                    "head": [0, 0, 0], "overrides": {"wave": "travelling"}})
    assert opts.overrides == {"wave": "travelling", "amplitude": 0.05} and opts.head == (0.0, 0.0, 0.0)
    assert CyclicOptions.from_dict(opts.to_dict()) == opts
    swim = opts.swim()
    assert (swim.mode, swim.frequency, swim.amplitude, swim.wave) == ("dolphin", 1.3, 0.05, "travelling")


@pytest.mark.parametrize("bad", [{"colour": 1}, {"n_curves": 2}, {"points": 4}, {"modes": 20},
                                 {"mode": "cod"}, {"frequency": 0}, {"a": 0.0}, {"a": 9.0},
                                 {"head": [1, 2]}, {"frames": "many"},
                                 {"overrides": [1]}, {"overrides": {"speed": 2}}])
def test_bad_options_raise(bad):
    with pytest.raises(ParameterError):
        CyclicOptions.from_dict(bad)


def test_capsule_clip_report_and_progress(capsule_mesh):
    stages = []
    parts = make_cyclic_clip(capsule_mesh, CyclicOptions(mode="eel", n_curves=20),
                             progress=lambda f, s: stages.append((f, s)))
    r = parts.report
    assert r["curves"] == 22 and r["patches"] == 7
    assert r["rest_distance"]["rel_mean"] < 3e-3 and r["rest_distance"]["rel_max"] < 2.5e-2  # the round caps
    assert stages[0][0] == 0.0 and stages[-1][0] == 1.0
    assert all(a[0] <= b[0] for a, b in zip(stages, stages[1:], strict=False))
    clip = load_clip(parts.topology, parts.coefficients)
    assert np.array_equal(clip.evaluate(0.0), capsule_mesh.vertices.astype(np.float32))


def test_same_input_same_bytes(capsule_mesh):
    opts = CyclicOptions(mode="shark", n_curves=10)
    a, b = make_cyclic_clip(capsule_mesh, opts), make_cyclic_clip(capsule_mesh, opts)
    assert a.topology == b.topology and a.coefficients == b.coefficients


def test_any_object_with_vertices_and_faces(trout_mesh):
    class Plain:
        vertices = trout_mesh.vertices
        faces = trout_mesh.faces

    parts = make_cyclic_clip(Plain(), CyclicOptions(mode="tropical", n_curves=13))
    assert parts.report["curves"] == 13


def test_bad_meshes_raise(trout_mesh):
    class Flat:
        vertices = np.random.default_rng(0).normal(size=(50, 3))
        faces = np.zeros((0, 3), int)

    with pytest.raises(MeshInputError):
        make_cyclic_clip(Flat(), CyclicOptions())
    with pytest.raises(MeshInputError):
        make_cyclic_clip(object(), CyclicOptions())

    ball = trimesh.creation.icosphere(2)

    with pytest.raises(InputError, match="elongated"):
        make_cyclic_clip(ball, CyclicOptions())
