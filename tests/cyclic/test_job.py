"""Cyclic job options and the whole pipeline on the generated meshes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.cyclic import shapes
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.errors import InputError, MeshInputError, ParameterError


def test_options_round_trip_and_flat_overrides():
    opts = CyclicOptions.from_dict({"mode": "dolphin", "amplitude": 0.05, "n_curves": 25,
                                    "head": [0, 0, 0], "overrides": {"wave": "travelling"}})
    assert opts.overrides == {"wave": "travelling", "amplitude": 0.05} and opts.head == (0.0, 0.0, 0.0)
    assert CyclicOptions.from_dict(opts.to_dict()) == opts
    swim = opts.swim()
    assert (swim.mode, swim.frequency, swim.amplitude, swim.wave) == ("dolphin", 1.3, 0.05, "travelling")


@pytest.mark.parametrize(
    "bad",
    [
        {"colour": 1},
        {"n_curves": 2},
        {"points": 4},
        {"modes": 20},
        {"mode": "cod"},
        {"frequency": 0},
        {"frequency": 1e9},
        {"a": 0.0},
        {"a": 9.0},
        {"head": [1, 2]},
        {"frames": "many"},
        {"overrides": [1]},
        {"overrides": {"speed": 2}},
    ],
)
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


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), aspect=st.floats(3.0, 8.0))
def test_any_orientation_of_a_capsule(seed, aspect):
    rot = Rotation.random(random_state=seed).as_matrix()
    mesh = shapes.capsule(length=aspect, radius=0.5, n_rings=30, n_around=16)
    verts = mesh.vertices @ rot.T + [1.0, -2.0, 3.0]

    class Turned:
        vertices = verts
        faces = mesh.faces

    parts = make_cyclic_clip(Turned(), CyclicOptions(mode="shark", n_curves=22))
    th, _ = container.unpack(parts.topology)
    assert abs(np.asarray(th["frame"]["axis"]) @ rot[:, 0]) > 1 - 1e-9
    assert parts.report["rest_distance"]["rel_mean"] < 5e-3
    clip = load_clip(parts.topology, parts.coefficients)
    assert np.array_equal(clip.evaluate(0.0), verts.astype(np.float32))
    sway = (clip.evaluate(0.25) - clip.evaluate(0.0)) @ rot[:, 0]
    assert np.abs(sway).max() < 0.05 * aspect  # the wave is sideways, not along the body


def test_real_mesh_spot_swims(spot_path):
    from pdeanim.mesh.io import load_mesh

    spot = load_mesh(spot_path)  # a cow: legs and ears give slices with several loops; the outer one is kept
    parts = make_cyclic_clip(spot, CyclicOptions(mode="tropical", n_curves=25))
    r = parts.report
    assert r["multi_loop_slices"] > 0 and r["rest_distance"]["rel_mean"] < 1e-2
    clip = load_clip(parts.topology, parts.coefficients)
    assert np.array_equal(clip.evaluate(0.0), spot.vertices.astype(np.float32))
    assert np.abs(clip.evaluate(1.0) - clip.evaluate(0.0)).max() < 1e-5
