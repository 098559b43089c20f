"""Odd mesh files: each gives a clear MeshInputError/TetrahedralizationError, never a crash or silent
damage."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.errors import LimitError, MeshInputError, TetrahedralizationError
from pdeanim.gltf.read import sample_times
from pdeanim.mesh.io import SurfaceMesh, load_mesh
from pdeanim.sim.tetra import TetParams, tetrahedralize

TET = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"


@pytest.mark.parametrize("face", ["f 0 1 2", "f 1 2 0", "f 1 0/1 2", "f\t0//1 2 3"])
def test_obj_vertex_index_zero_is_refused(face: str) -> None:
    """OBJ indices start at 1: trimesh would silently wrap 0 to the last vertex."""
    with pytest.raises(MeshInputError, match="index 0"):
        load_mesh((TET + "f 1 2 3\n" + face + "\n").encode(), filename="bad.obj")


def test_obj_negative_and_texture_indices_still_load() -> None:
    """Negative (relative) indices and a texture index 0 in v/vt are not vertex index 0."""
    text = TET + "vt 0 0\nvt 1 0\nf -4 -2 -3\nf 1 2 4\nf 1 4 3\nf 2/1 3/2 4/1\n"
    mesh = load_mesh(text.encode(), filename="ok.obj")
    assert mesh.faces.shape == (4, 3) and mesh.faces.min() >= 0


def test_flat_surface_with_stray_vertex_is_refused_before_tetwild() -> None:
    """A single triangle plus an unreferenced off-plane vertex encloses no volume: clear error, no fTetWild
    run."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    mesh = SurfaceMesh(vertices, np.array([[0, 1, 2]], np.int64))
    with pytest.raises(TetrahedralizationError, match="flat"):
        tetrahedralize(mesh, TetParams(target_tets=200))


def test_frame_limit_names_a_whole_frame_count() -> None:
    """The limit message counts frames as an integer (not 366667.67)."""
    with pytest.raises(LimitError) as info:
        sample_times(0.0, 11 / 30, 1e6, max_frames=10_000)
    assert isinstance(info.value.value, int) and info.value.value == 366668
