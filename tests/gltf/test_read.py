"""Reading animated glTF: morph round trips of animation_glb, skinned bars with weights that do not sum to
1 (renormalised and reported), node-transform animation, STEP/LINEAR/CUBICSPLINE sampling, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.errors import LimitError, MeshInputError, ParameterError, PosesInputError
from pdeanim.gltf.read import read_animated_poses, read_static_mesh, sample_times
from pdeanim.gltf.sampling import sample, slerp
from pdeanim.gltf.skin import joint_world_matrices, load_skinned, skin_vertices
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.write import animation_glb, frame_glb
from pdeanim.posefiles import load_poses
from pdeanim.poses import PoseLimits

from .builders import expected_bar, skinned_bar_glb, sparse_morph_glb, two_node_glb


def test_morph_round_trip_float32_exact(morph):
    frames, faces, times = morph
    poses = read_animated_poses(animation_glb(frames, times, faces), fps=30)
    assert poses.vertices.shape == frames.shape
    np.testing.assert_allclose(poses.vertices, frames, rtol=0, atol=2e-6)  # base + one-hot delta in float32
    np.testing.assert_array_equal(poses.faces, faces)
    np.testing.assert_allclose(poses.times, times - times[0], atol=1e-6)
    assert poses.meta["animation"]["channels"] == ["weights"]


def test_morph_round_trip_quantised_and_looping(morph, tmp_path):
    frames, faces, times = morph
    sub, t = frames[::10], np.arange(len(frames[::10])) / 10.0
    glb = animation_glb(sub, t, faces, quantize=True, loop=True)
    path = tmp_path / "loop.glb"
    path.write_bytes(glb)
    poses = load_poses(path, fps=10)  # pdeanim.posefiles dispatches .glb here
    span = float(np.ptp(sub.reshape(-1, 3), axis=0).max())
    np.testing.assert_allclose(poses.vertices[: len(sub)], sub, atol=span / 32766)
    np.testing.assert_allclose(poses.vertices[-1], poses.vertices[0], atol=1e-7)  # closing key = first frame


@pytest.mark.parametrize("interpolation", ["LINEAR", "CUBICSPLINE"])
def test_skinned_bar_matches_analytic_lbs(interpolation):
    poses = read_animated_poses(skinned_bar_glb(interpolation), fps=4)
    assert poses.n_frames == 5 and poses.n_vertices == 10
    for k, t in enumerate(poses.times):
        if interpolation == "LINEAR":
            angle = np.pi / 2 * t  # slerp: constant angular speed
        else:  # Hermite with zero tangents on quaternion components, then normalised
            s = 3 * t**2 - 2 * t**3
            angle = 2 * np.arctan2(s * np.sqrt(0.5), (1 - s) + s * np.sqrt(0.5))
        np.testing.assert_allclose(poses.vertices[k], expected_bar(angle), atol=1e-6)
    report = poses.meta["skin_weights"][0]
    assert report["renormalised"] == 6 and report["zero_weight_vertices"] == 0
    assert report["max_sum_deviation"] == pytest.approx(0.5)


def test_skin_api_drives_joints():
    skinned = load_skinned(skinned_bar_glb())
    assert skinned.joint_names == ["root", "tip"] and list(skinned.joint_parents) == [-1, 0]
    np.testing.assert_allclose(skinned.vertex_weights.sum(axis=1), 1.0)
    rest = skin_vertices(skinned, joint_world_matrices(skinned))
    np.testing.assert_allclose(rest, expected_bar(0.0), atol=1e-6)
    angles = np.array([0.3, 1.2])
    quats = np.stack([np.zeros(2), np.zeros(2), np.sin(angles / 2), np.cos(angles / 2)], axis=1)
    world = joint_world_matrices(skinned, {"tip": {"rotation": quats}})
    assert world.shape == (2, 2, 4, 4)
    moved = skin_vertices(skinned, world)
    for k, a in enumerate(angles):
        np.testing.assert_allclose(moved[k], expected_bar(a), atol=1e-6)
    lifted = skin_vertices(skinned, joint_world_matrices(skinned, {0: {"translation": [0, 0, 1.0]}}))
    np.testing.assert_allclose(lifted, expected_bar(0.0) + [0, 0, 1], atol=1e-6)
    with pytest.raises(MeshInputError):
        joint_world_matrices(skinned, {"elbow": {"rotation": [0, 0, 0, 1]}})


def test_joints_with_a_non_joint_node_between_them():
    from pdeanim.gltf.document import load_document
    from pdeanim.gltf.scene import world_matrices

    glb = skinned_bar_glb(middle=True)
    poses = read_animated_poses(glb, fps=4)
    for k, t in enumerate(poses.times):
        np.testing.assert_allclose(poses.vertices[k], expected_bar(np.pi / 2 * t), atol=1e-6)
    skinned = load_skinned(glb)
    assert list(skinned.joint_parents) == [-1, 0]
    scene = world_matrices(load_document(glb), {}, np.zeros(1))[0]
    np.testing.assert_allclose(joint_world_matrices(skinned), scene[skinned.joint_nodes], atol=1e-12)


def test_node_transform_animation_concatenates_meshes():
    poses = read_animated_poses(two_node_glb(), fps=2)
    assert poses.n_frames == 5 and poses.n_vertices == 6 and len(poses.faces) == 2
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    for k, t in enumerate(poses.times):
        np.testing.assert_allclose(poses.vertices[k, :3], tri * [1, 1, 3])
        np.testing.assert_allclose(poses.vertices[k, 3:], tri * 2 + [5, 0, t], atol=1e-6)
    static_v, static_f = read_static_mesh(two_node_glb())
    np.testing.assert_allclose(static_v[3:], tri * 2 + [5, 0, 0])
    np.testing.assert_array_equal(static_f, [[0, 1, 2], [3, 4, 5]])


def test_sparse_morph_target_with_step_weights():
    poses = read_animated_poses(sparse_morph_glb(), fps=2)
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32) * 2
    np.testing.assert_array_equal(poses.vertices[0], quad)
    np.testing.assert_array_equal(poses.vertices[1], quad)  # STEP holds the first key until t = 1
    np.testing.assert_array_equal(poses.vertices[2], quad + [[0, 0, 0], [0, 0, 0], [0, 0, 2], [0, 0, 0]])


def test_compressed_geometry_is_refused_clearly():
    from pdeanim.gltf.glb import pack_glb, unpack_glb

    doc, binary = unpack_glb(sparse_morph_glb())
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_meshopt_compression"]  # Draco: test_draco.py
    with pytest.raises(PosesInputError, match="KHR_meshopt_compression"):
        read_animated_poses(pack_glb(doc, binary))


def test_hand_built_assets_have_only_the_intended_defects():
    bar, cubic, nodes, sparse = validate_many(
        [skinned_bar_glb(), skinned_bar_glb("CUBICSPLINE"), two_node_glb(), sparse_morph_glb()]
    )
    assert_clean(nodes, "two nodes")
    assert_clean(sparse, "sparse morph")
    for report in (
        bar,
        cubic,
    ):  # weights that do not sum to 1 and a transform on the skinned node, on purpose
        codes = {m["code"] for m in report["issues"]["messages"]}
        assert codes == {"ACCESSOR_WEIGHTS_NON_NORMALIZED", "NODE_SKINNED_MESH_LOCAL_TRANSFORMS"}


def test_step_and_cubic_sampling():
    keys = np.array([0.0, 1.0, 3.0])
    vals = np.array([[0.0], [2.0], [4.0]])
    t = np.array([-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 9.0])
    np.testing.assert_allclose(sample(keys, vals, "STEP", t)[:, 0], [0, 0, 0, 2, 2, 4, 4])
    np.testing.assert_allclose(sample(keys, vals, "LINEAR", t)[:, 0], [0, 0, 1, 2, 3, 4, 4])
    cubic = np.array([[0.0], [0.0], [1.0], [1.0], [2.0], [1.0], [1.0], [4.0], [0.0]])  # in, value, out
    got = sample(keys, cubic, "CUBICSPLINE", np.array([0.5]))[0, 0]
    s = 0.5
    assert got == pytest.approx((2 * s**3 - 3 * s**2 + 1) * 0 + (s**3 - 2 * s**2 + s) * 1
                                + (-2 * s**3 + 3 * s**2) * 2 + (s**3 - s**2) * 1)
    with pytest.raises(PosesInputError):
        sample(np.array([0.0, 0.0]), vals[:2], "LINEAR", t)


unit_quats = st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=60, deadline=None)
@given(unit_quats, unit_quats, st.floats(0, 1))
def test_slerp_is_unit_and_hits_endpoints(a, b, s):
    q0, q1 = np.array([a]), np.array([b])
    out = slerp(q0, q1, np.array([s]))
    assert abs(np.linalg.norm(out) - 1) < 1e-9
    e0, e1 = slerp(q0, q1, np.array([0.0])), slerp(q0, q1, np.array([1.0]))
    n0, n1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    assert np.allclose(e0, n0)
    assert np.allclose(e1, n1) or np.allclose(e1, -n1)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.01, 10), st.floats(1, 120))
def test_sample_times_cover_range(duration, fps):
    t = sample_times(1.0, 1.0 + duration, fps)
    assert t[0] == 1.0 and abs(t[-1] - (1.0 + duration)) < 1e-6 and np.all(np.diff(t) > 0)


def test_bad_inputs_raise_input_errors(spot, morph):
    v, f = spot
    with pytest.raises(PosesInputError, match="no animation"):
        read_animated_poses(frame_glb(v, f))
    with pytest.raises(PosesInputError):
        read_animated_poses(b"not a gltf file at all")
    with pytest.raises(PosesInputError):
        read_animated_poses(frame_glb(v, f)[:100])
    frames, faces, times = morph
    glb = animation_glb(frames[:20], times[:20], faces)
    with pytest.raises(LimitError):
        read_animated_poses(glb, limits=PoseLimits(max_frames=5))
    with pytest.raises(ParameterError):
        read_animated_poses(glb, fps=0)
    with pytest.raises(PosesInputError, match="no animation named"):
        read_animated_poses(glb, animation="walk")


def test_khronos_simple_skin_sample(tmp_path):
    """The CC0 SimpleSkin sample (embedded .gltf): two joints, the child turning about z around (0, 1, 0)."""
    import base64
    import json
    from pathlib import Path

    path = Path(__file__).parent / "data" / "SimpleSkin.gltf"
    doc = json.loads(path.read_text())
    raw = [base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]
    rest = np.frombuffer(raw[0], np.float32, 30, 48).reshape(10, 3).astype(np.float64)
    weights = np.frombuffer(raw[1], np.float32, 40, 160).reshape(10, 4)[:, :2].astype(np.float64)
    keys = np.frombuffer(raw[3], np.float32, 12, 0)
    quats = np.frombuffer(raw[3], np.float32, 48, 48).reshape(12, 4).astype(np.float64)
    poses = read_animated_poses(path, fps=2)  # the keys lie on the 2 fps grid
    np.testing.assert_allclose(poses.times, keys)
    pivot = np.array([0.0, 1.0, 0.0])
    for k, q in enumerate(quats):
        a = 2 * np.arctan2(q[2], q[3])
        rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        want = weights[:, :1] * rest + weights[:, 1:] * ((rest - pivot) @ rot.T + pivot)
        np.testing.assert_allclose(poses.vertices[k], want, atol=2e-6)
    assert poses.faces.shape == (8, 3) and poses.meta["skin_weights"][0]["renormalised"] == 0
    half = read_animated_poses(path.read_bytes(), fps=4)  # bytes work too (data URIs need no folder)
    assert half.n_frames == 23


JUNK = [None, -1, 10**9, "x", [], {}, 0.5, [1, 2], True, 2]


def _mutate(node, rng: np.random.Generator) -> None:
    """Replace one randomly chosen value deep inside a JSON tree with junk."""
    keys = list(node) if isinstance(node, dict) else list(range(len(node)))
    if not keys:
        return
    key = keys[rng.integers(len(keys))]
    child = node[key]
    if isinstance(child, dict | list) and child and rng.random() > 0.35:
        _mutate(child, rng)
    else:
        node[key] = JUNK[rng.integers(len(JUNK))]


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["bar", "nodes", "sparse"]), st.booleans())
def test_malformed_files_raise_input_errors_only(seed, which, json_level):
    from pdeanim.errors import InputError
    from pdeanim.gltf.glb import pack_glb, unpack_glb

    base = {"bar": skinned_bar_glb, "nodes": two_node_glb, "sparse": sparse_morph_glb}[which]()
    rng = np.random.default_rng(seed)
    if json_level:
        doc, binary = unpack_glb(base)
        _mutate(doc, rng)
        data = pack_glb(doc, binary)
    else:
        raw = bytearray(base)
        for _ in range(rng.integers(1, 5)):
            raw[rng.integers(len(raw))] = rng.integers(256)
        data = bytes(raw)
    for reader in (lambda d: read_animated_poses(d, fps=4), load_skinned, read_static_mesh):
        try:
            reader(data)
        except InputError:
            pass
