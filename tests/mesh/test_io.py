"""Mesh ingestion: every supported format, the stats, seam merging, and a clear error for every bad input."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pdeanim.errors import LimitError, MeshInputError
from pdeanim.mesh.io import MeshLimits, SurfaceMesh, load_mesh

TRIANGLE = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


@pytest.fixture(scope="module")
def spot(spot_path) -> SurfaceMesh:
    return load_mesh(spot_path)


def export_bytes(mesh: SurfaceMesh, ext: str) -> bytes:
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    data = tm.export(file_type=ext)
    return data.encode() if isinstance(data, str) else data


def test_spot_and_bob_keep_file_order_and_report_stats(spot, spot_path, bob_path):
    lines = [ln.split() for ln in spot_path.read_text().splitlines() if ln.startswith("v ")]
    file_vertices = np.array([[float(x) for x in ln[1:4]] for ln in lines])
    assert spot.vertices.shape == (2930, 3) and spot.vertices.dtype == np.float64
    np.testing.assert_array_equal(spot.vertices, file_vertices)
    assert spot.faces.shape == (5856, 3) and spot.faces.dtype == np.int64
    stats = spot.stats()
    assert stats["vertices"] == 2930 and stats["faces"] == 5856
    assert stats["components"] == 1 and stats["watertight"] is True
    np.testing.assert_allclose(stats["bbox"]["min"], file_vertices.min(axis=0))
    assert stats["diagonal"] == pytest.approx(np.linalg.norm(np.ptp(file_vertices, axis=0)))
    bob = load_mesh(bob_path)
    assert bob.stats()["vertices"] == 5344 and bob.stats()["watertight"]


@pytest.mark.parametrize("ext", ["ply", "off", "glb"])
def test_indexed_formats_roundtrip(spot, ext):
    mesh = load_mesh(export_bytes(spot, ext), filename=f"spot.{ext}")
    np.testing.assert_allclose(mesh.vertices, spot.vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, spot.faces)
    assert mesh.content_hash == load_mesh(export_bytes(spot, ext), filename=f"x.{ext}").content_hash


def test_stl_seams_merge_with_a_map_back(spot):
    raw = load_mesh(export_bytes(spot, "stl"), filename="spot.stl")
    assert raw.vertices.shape == (3 * 5856, 3)
    merged = load_mesh(export_bytes(spot, "stl"), filename="spot.stl", merge_seams=True)
    assert merged.vertices.shape == (2930, 3) and merged.stats()["watertight"]
    np.testing.assert_array_equal(merged.vertices[merged.original_index], raw.vertices)
    np.testing.assert_array_equal(merged.original_index[raw.faces], merged.faces)


def test_gltf_scene_is_flattened_with_node_transforms(tmp_path):
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(), node_name="moved",
                       transform=trimesh.transformations.translation_matrix([5, 0, 0]))
    scene.add_geometry(trimesh.creation.box(), node_name="origin")
    data = scene.export(file_type="gltf", embed_buffers=True)["model.gltf"]
    mesh = load_mesh(data, filename="scene.gltf")
    stats = mesh.stats()
    assert stats["components"] == 2 and stats["faces"] == 24
    np.testing.assert_allclose(stats["bbox"]["max"], [5.5, 0.5, 0.5])
    path = tmp_path / "scene.glb"
    path.write_bytes(scene.export(file_type="glb"))
    assert load_mesh(path).stats()["bbox"]["min"] == [-0.5, -0.5, -0.5]


def test_merge_keeps_indexed_mesh_unchanged(spot_path, spot):
    merged = load_mesh(spot_path, merge_seams=True)
    np.testing.assert_array_equal(merged.vertices, spot.vertices)
    np.testing.assert_array_equal(merged.original_index, np.arange(2930))


@pytest.mark.parametrize(("data", "name", "needle"), [
    (b"", "a.obj", "empty"),
    (b"v 0 0 0\nv 1 0 0\n", "a.obj", "no triangle"),
    (b"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "a.obj", "NaN or infinite"),
    (b"v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "a.obj", "NaN or infinite"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "a.obj", "out of range"),
    (b"hello, not a mesh\n", "a.ply", "cannot parse"),
    (b"hello, not a mesh\n", "a.glb", "cannot parse"),
    (b"hello, not a mesh\n", "a.off", "cannot parse"),
    (b"hello, not a mesh\n", "a.stl", "no triangle"),
    (TRIANGLE, "a.fbx", "unsupported mesh file type"),
    (TRIANGLE, "noextension", "unsupported mesh file type"),
])
def test_bad_inputs_name_the_problem(data, name, needle):
    with pytest.raises(MeshInputError, match=needle):
        load_mesh(data, filename=name)


@pytest.mark.parametrize("ext", ["ply", "glb", "off", "stl"])
def test_truncated_files_are_rejected(spot, ext):
    data = export_bytes(spot, ext)
    with pytest.raises(MeshInputError):
        load_mesh(data[: len(data) // 2], filename=f"cut.{ext}")


def test_missing_path_is_an_input_error(tmp_path):
    with pytest.raises(MeshInputError, match="does not exist"):
        load_mesh(tmp_path / "nothing.obj")


def test_limits_name_their_setting(spot_path):
    with pytest.raises(LimitError, match="PDEANIM_MAX_MESH_BYTES"):
        load_mesh(spot_path, limits=MeshLimits(max_file_bytes=1000))
    with pytest.raises(LimitError, match="PDEANIM_MAX_VERTICES") as info:
        load_mesh(spot_path, limits=MeshLimits(max_vertices=100))
    assert info.value.value == 2930 and info.value.limit == 100
    with pytest.raises(LimitError, match="PDEANIM_MAX_FACES"):
        load_mesh(spot_path.read_bytes(), filename="spot.obj", limits=MeshLimits(max_faces=10))


def test_single_triangle_stats():
    mesh = load_mesh(TRIANGLE, filename="t.obj")
    assert mesh.stats()["watertight"] is False and mesh.stats()["components"] == 1


def test_gltf_on_disk_reads_its_external_buffers_but_bytes_do_not(tmp_path):
    files = trimesh.creation.box().export(file_type="gltf")  # model.gltf + external .bin buffers
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    mesh = load_mesh(tmp_path / "model.gltf")
    assert mesh.stats()["faces"] == 12 and mesh.stats()["watertight"]
    with pytest.raises(MeshInputError):
        load_mesh(files["model.gltf"], filename="model.gltf")
