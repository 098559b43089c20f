"""GLB writing: structure, exact bounds, alignment, normals, and 0 errors / 0 warnings from the Khronos
validator on real outputs (spot.obj, AnimatedMorphSphere frames, unreferenced vertices, points, quantised)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.errors import ParameterError
from pdeanim.gltf.glb import COMPONENT_DTYPES, TYPE_SIZES, unpack_glb
from pdeanim.gltf.normals import vertex_normals, vertex_normals_frames
from pdeanim.gltf.read import read_animated_poses
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.write import animation_glb, frame_glb


def accessor(doc: dict, binary: bytes, index: int) -> np.ndarray:
    """Decode a (non-sparse) accessor of a GLB written here, honouring byteStride."""
    acc = doc["accessors"][index]
    width = TYPE_SIZES[acc["type"]]
    dtype = COMPONENT_DTYPES[acc["componentType"]]
    if "bufferView" not in acc:
        return np.zeros((acc["count"], width), dtype)
    view = doc["bufferViews"][acc["bufferView"]]
    stride = view.get("byteStride", width * dtype.itemsize) // dtype.itemsize
    raw = np.frombuffer(binary, dtype, count=view["byteLength"] // dtype.itemsize, offset=view["byteOffset"])
    return raw.reshape(acc["count"], stride)[:, :width]


def check_layout(glb: bytes) -> tuple[dict, bytes]:
    """Header length exact, chunks and views 4-byte aligned, exact bounds on every accessor that has them."""
    assert struct.unpack_from("<4sII", glb)[2] == len(glb) and len(glb) % 4 == 0
    json_len = struct.unpack_from("<I", glb, 12)[0]
    assert json_len % 4 == 0
    doc, binary = unpack_glb(glb)
    if binary is not None:
        assert len(binary) % 4 == 0 and doc["buffers"][0]["byteLength"] == len(binary)
    for view in doc.get("bufferViews", []):
        assert view["byteOffset"] % 4 == 0
        assert view["byteOffset"] + view["byteLength"] <= len(binary)
    for i, acc in enumerate(doc.get("accessors", [])):
        if "min" in acc:
            data = accessor(doc, binary, i)
            assert acc["min"] == data.min(axis=0).tolist() and acc["max"] == data.max(axis=0).tolist()
    return doc, binary


def test_frame_glb_spot_round_trip(spot):
    v, f = spot
    doc, binary = check_layout(frame_glb(v, f))
    prim = doc["meshes"][0]["primitives"][0]
    np.testing.assert_array_equal(accessor(doc, binary, prim["attributes"]["POSITION"]), v)
    assert doc["accessors"][prim["indices"]]["componentType"] == 5123  # < 65535 vertices: UNSIGNED_SHORT
    np.testing.assert_array_equal(accessor(doc, binary, prim["indices"]).reshape(-1, 3), f)
    n = accessor(doc, binary, prim["attributes"]["NORMAL"])
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


def reference_normals(p: np.ndarray, f: np.ndarray) -> np.ndarray:
    p = p.astype(np.float64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    acc = np.zeros_like(p)
    for c in range(3):
        np.add.at(acc, f[:, c], fn)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


def test_normals_match_area_weighted_reference(spot, morph):
    v, f = spot
    np.testing.assert_allclose(vertex_normals(v, f), reference_normals(v, f), atol=1e-6)
    frames, mf, _ = morph
    both = vertex_normals_frames(frames[:3], mf)
    # 1 frame/chunk
    np.testing.assert_array_equal(vertex_normals_frames(frames[:3], mf, chunk_values=10), both)
    for k in range(3):
        np.testing.assert_allclose(both[k], vertex_normals(frames[k], mf), atol=1e-6)


def test_normals_fallback_for_isolated_and_degenerate():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [2, 2, 2], [2, 2, 2]], np.float32)
    f = np.array([[0, 1, 2], [4, 5, 4]])
    n = vertex_normals(p, f)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(n[0], [0, 0, 1], atol=1e-6)
    assert np.all(np.isfinite(n))


def test_large_mesh_uses_uint_indices():
    n = 70_000
    p = np.random.default_rng(0).normal(size=(n, 3)).astype(np.float32)
    f = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], axis=1)
    doc, binary = check_layout(frame_glb(p, f))
    idx = doc["meshes"][0]["primitives"][0]["indices"]
    assert doc["accessors"][idx]["componentType"] == 5125
    np.testing.assert_array_equal(accessor(doc, binary, idx).reshape(-1, 3), f)


def test_animation_structure_and_loop(morph):
    frames, f, times = morph
    k = 12
    doc, binary = check_layout(animation_glb(frames[:k], times[:k] + 3.0, f))
    prim = doc["meshes"][0]["primitives"][0]
    assert len(prim["targets"]) == k and len(doc["meshes"][0]["extras"]["targetNames"]) == k
    sampler = doc["animations"][0]["samplers"][0]
    key_t = accessor(doc, binary, sampler["input"])[:, 0]
    assert key_t[0] == 0 and np.all(np.diff(key_t) > 0) and key_t.dtype == np.float32
    w = accessor(doc, binary, sampler["output"]).reshape(k, k)
    np.testing.assert_array_equal(w, np.eye(k, dtype=np.float32))
    base = accessor(doc, binary, prim["attributes"]["POSITION"])
    for i in (0, 5, k - 1):
        np.testing.assert_allclose(base + accessor(doc, binary, prim["targets"][i]["POSITION"]), frames[i],
                                   atol=1e-6)
    closed = np.concatenate([frames[:k], frames[:1]])
    doc2, binary2 = check_layout(animation_glb(closed, np.arange(k + 1) / 30, f, loop=True))
    s2 = doc2["animations"][0]["samplers"][0]
    w2 = accessor(doc2, binary2, s2["output"]).reshape(k + 1, k)
    np.testing.assert_array_equal(w2[-1], w2[0])  # the closing key shows the first frame exactly
    doc3, binary3 = check_layout(animation_glb(frames[:k], times[:k], f, loop=True))
    w3 = accessor(doc3, binary3, doc3["animations"][0]["samplers"][0]["output"]).reshape(k + 1, k)
    np.testing.assert_array_equal(w3[-1], w3[0])


def test_quantised_positions_within_half_a_step(morph):
    frames, f, times = morph
    doc, binary = check_layout(animation_glb(frames[::20], times[::20], f, quantize=True))
    assert doc["extensionsRequired"] == ["KHR_mesh_quantization"]
    node = doc["nodes"][0]
    prim = doc["meshes"][0]["primitives"][0]
    base = accessor(doc, binary, prim["attributes"]["POSITION"]).astype(np.float64)
    step = node["scale"][0] / 32767
    for i, frame in enumerate(frames[::20]):
        q = base + accessor(doc, binary, prim["targets"][i]["POSITION"])
        world = np.asarray(node["translation"]) + q * step
        assert np.abs(world - frame).max() <= 0.5 * step * 1.0001


def test_bad_input_raises_parameter_error(morph):
    frames, f, _ = morph
    with pytest.raises(ParameterError):
        animation_glb(frames[:3], [0.0, 0.0, 1.0], f)
    with pytest.raises(ParameterError):
        frame_glb(np.full((3, 3), np.nan), None)
    with pytest.raises(ParameterError):
        frame_glb(frames[0], f + 10_000)


def test_every_written_glb_is_validator_clean(spot, morph):
    v, f = spot
    frames, mf, times = morph
    used = f[f.max(axis=1) < len(v) // 2]  # half the vertices left unreferenced
    blobs = {
        "spot frame": frame_glb(v, f),
        "unreferenced vertices": frame_glb(v, used),
        "points": frame_glb(v[:100], None),
        "degenerate faces": frame_glb(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]])),
        "morph sphere animation": animation_glb(frames[::4], times[::4], mf),
        "morph sphere quantised": animation_glb(frames[::4], times[::4], mf, quantize=True),
        "morph sphere loop": animation_glb(frames[:30], times[:30], mf, loop=True, quantize=True),
        "points animation": animation_glb(frames[:5, :50], times[:5], None),
        "single frame animation": animation_glb(frames[:1], times[:1], mf),
        "unreferenced animation": animation_glb(np.stack([v, v * 1.1]), [0, 1], used, quantize=True),
        "no target normals": animation_glb(frames[::8], times[::8], mf, normals=False, quantize=True),
    }
    for label, report in zip(blobs, validate_many(list(blobs.values())), strict=True):
        assert_clean(report, label)


@st.composite
def animations(draw):
    """Small random animations: K frames of V vertices, some faces, strictly increasing times."""
    k, v = draw(st.integers(1, 5)), draw(st.integers(3, 30))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    scale = draw(st.sampled_from([1e-3, 1.0, 250.0]))
    frames = (rng.normal(size=(k, v, 3)) * scale + rng.normal(size=3) * scale * 10).astype(np.float32)
    faces = rng.integers(0, v, size=(draw(st.integers(0, 40)), 3))
    steps = np.cumsum(rng.integers(1, 5, size=k)) - 1  # key times on a 10 fps grid, uneven gaps
    return frames, steps / 10 + draw(st.integers(0, 100)), faces


@settings(max_examples=40, deadline=None)
@given(animations(), st.booleans())
def test_any_animation_round_trips_with_exact_bounds(anim, quantize):
    frames, times, faces = anim
    glb = animation_glb(frames, times, faces, quantize=quantize)
    check_layout(glb)
    back = read_animated_poses(glb, fps=10.0)  # the grid samples every key
    idx = np.rint((times - times[0]) * 10).astype(np.int64)
    assert back.n_frames == idx[-1] + 1
    span = float(np.abs(frames).max()) or 1.0
    tol = span / 16000 if quantize else span * 1e-6
    np.testing.assert_allclose(back.vertices[idx], frames, atol=tol, rtol=0)
