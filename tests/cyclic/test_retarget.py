"""Mapping mesh vertices onto the PDE surface and carrying them along."""

from __future__ import annotations

import numpy as np

from pdeanim.cyclic.body import body_frame, cut_body
from pdeanim.cyclic.chain import BodySurface
from pdeanim.cyclic.retarget import map_to_surface, move_with_surface


def _surface(mesh, n_curves=37):
    frame = body_frame(mesh.vertices)
    return BodySurface.from_curves(cut_body(mesh.vertices, mesh.faces, frame, n_curves, 32).curves)


def test_surface_points_map_to_themselves(trout_mesh):
    surface = _surface(trout_mesh)
    rng = np.random.default_rng(2)
    s, v = rng.uniform(0.05, 0.95, 200), rng.uniform(0, 2 * np.pi, 200)
    pts = surface.evaluate(s, v)
    vm = map_to_surface(surface, pts)
    assert vm.distance.max() < 1e-6
    assert np.abs(surface.evaluate(vm.s, vm.v) + vm.offset - pts).max() < 1e-12


def test_mesh_vertices_are_close_and_offsets_consistent(trout_mesh):
    surface = _surface(trout_mesh)
    vm = map_to_surface(surface, trout_mesh.vertices)
    diag = trout_mesh.diagonal()
    assert vm.distance.mean() < 2e-3 * diag and vm.distance.max() < 2e-2 * diag
    assert np.abs(surface.evaluate(vm.s, vm.v) + vm.offset - trout_mesh.vertices).max() < 1e-12
    patch, u = vm.patch_u(surface.n_patches)
    assert np.allclose((patch + u) / surface.n_patches, vm.s)


def test_rest_pose_is_reproduced_exactly(trout_mesh):
    out = move_with_surface(trout_mesh.vertices, np.zeros_like(trout_mesh.vertices))
    assert out.dtype == np.float32
    assert np.array_equal(out, trout_mesh.vertices.astype(np.float32))
    frames = move_with_surface(trout_mesh.vertices, np.zeros((3, *trout_mesh.vertices.shape)))
    assert frames.shape == (3, *trout_mesh.vertices.shape)
