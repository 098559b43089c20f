"""The fast frame path of the service: per-topology normals (CSR incidence) and the preallocated frame GLB
writer give the same files as the general GLB builder, clean for the Khronos validator."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.errors import ParameterError
from pdeanim.gltf.glb import ARRAY_BUFFER, GlbBuilder, unpack_glb
from pdeanim.gltf.normals import FaceNormals, vertex_normals
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.write import FrameGlb


@pytest.fixture(scope="module")
def spot(spot_path):
    mesh = trimesh.load(spot_path, process=False)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int64)


def reference_glb(p: np.ndarray, f: np.ndarray) -> bytes:
    """The frame GLB built with the general builder and the float64 normals."""
    b = GlbBuilder()
    attrs = {"POSITION": b.add_accessor(p, target=ARRAY_BUFFER, minmax=True),
             "NORMAL": b.add_accessor(vertex_normals(p, f), target=ARRAY_BUFFER)}
    prim = {"attributes": attrs, "mode": 4,
            "indices": b.add_accessor(f.reshape(-1).astype(np.uint16), target=34963, acc_type="SCALAR")}
    b.doc.update(meshes=[{"primitives": [prim]}], nodes=[{"mesh": 0}], scenes=[{"nodes": [0]}], scene=0)
    return b.to_glb()


def wave(p: np.ndarray, phase: float) -> np.ndarray:
    """A smooth deformation of the rest shape (a frame a clip could produce)."""
    return (p + 0.1 * np.sin(3.0 * p[:, [1, 2, 0]] + phase)).astype(np.float32)


@settings(max_examples=20, deadline=None)
@given(phase=st.floats(0, 2 * np.pi), scale=st.floats(1e-3, 1e3))
def test_face_normals_match_the_float64_normals(spot, phase, scale):
    p, f = spot
    q = wave(p, phase) * np.float32(scale)
    normals = FaceNormals(f, len(p))
    got = normals(q)
    assert got.dtype == np.float32 and got.shape == q.shape
    np.testing.assert_allclose(got, vertex_normals(q, f), atol=2e-5)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-6)


def test_face_normals_fall_back_for_vertices_no_face_touches(spot):
    p, f = spot
    q = np.vstack([p, [[5.0, 5.0, 5.0]]]).astype(np.float32)  # one unreferenced vertex
    np.testing.assert_array_equal(FaceNormals(f, len(q))(q), vertex_normals(q, f))


def test_frame_writer_matches_the_general_builder(spot):
    p, f = spot
    writer = FrameGlb(f, len(p))
    for phase in (0.0, 1.0, 2.5):  # the same writer, frame after frame
        q = wave(p, phase)
        got, ref = unpack_glb(writer(q)), unpack_glb(reference_glb(q, f))
        assert got[0] == ref[0]  # identical glTF JSON, bounds included
        g, r = (np.frombuffer(x[1], np.uint8) for x in (got, ref))
        n = 12 * len(p)
        assert np.array_equal(g[:n], r[:n]) and np.array_equal(g[2 * n:], r[2 * n:])  # positions, indices
        np.testing.assert_allclose(g[n: 2 * n].view(np.float32), r[n: 2 * n].view(np.float32), atol=2e-5)
    fresh = FrameGlb(f, len(p))(p)  # the reused buffer keeps nothing of the earlier frames
    assert writer(p) == fresh and unpack_glb(fresh)[0] == unpack_glb(reference_glb(p, f))[0]


def test_frame_writer_output_is_validator_clean(spot):
    p, f = spot
    points = np.random.default_rng(0).normal(size=(50, 3)).astype(np.float32)
    blobs = [FrameGlb(f, len(p))(wave(p, 0.7)), FrameGlb(None, 50)(points)]
    for report, label in zip(validate_many(blobs), ("spot frame", "points"), strict=True):
        assert_clean(report, label)


def test_frame_writer_rejects_bad_frames(spot):
    p, f = spot
    writer = FrameGlb(f, len(p))
    with pytest.raises(ParameterError):
        writer(p[:-1])
    bad = p.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ParameterError):
        writer(bad)
    with pytest.raises(ParameterError):
        FrameGlb(f, 10)
