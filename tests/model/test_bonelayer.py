"""The bone layer (format 1.1, docs/format.md §3.9): skinning, the time fit and quantisation of the bone
tracks, their stored form and its rejections, and a clip with bones read back and evaluated as §3.9 says."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.clip import load_clip, read_clip_file, write_clip_file
from pdeanim.errors import ClipFormatError
from pdeanim.model.bonelayer import (
    TIME_SPLINE,
    BoneMotion,
    BoneTracks,
    bones_header_arrays,
    coarse_mu,
    decode_bones,
    encode_bones,
    repack_with_bone_layer,
    skin,
    skinned_positions,
    sorted_influences,
    unwrap_rotvec,
    weight_levels,
)
from pdeanim.model.rigid import rodrigues
from tests.conformance.bonecases import bend_motion, synthetic_bones

HEADER = {"kind": "dynamic-pde", "motion": "displacement"}


def _random_motion(rng: np.random.Generator, V: int, B: int, K: int, F: int, scale: float = 1.0
                   ) -> tuple[np.ndarray, BoneMotion]:
    rest = rng.normal(0.0, 1.0, (V, 3))
    index = rng.integers(0, B, (V, K))
    w = rng.uniform(0.05, 1.0, (V, K))
    motion = BoneMotion(rng.normal(0.0, 0.5, (B, 3)), index, w / w.sum(1, keepdims=True),
                        scale * rng.normal(0.0, 0.8, (F, B, 3)), scale * rng.normal(0.0, 0.3, (F, B, 3)))
    return rest, motion


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 40), st.integers(1, 6), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_skin_of_identity_transforms_is_the_rest_pose(V, B, K, seed):
    rng = np.random.default_rng(seed)
    rest, m = _random_motion(rng, V, B, K, 2)
    still = BoneMotion(m.pivot, m.index, m.weight, np.zeros((2, B, 3)), np.zeros((2, B, 3)))
    np.testing.assert_allclose(skin(still, rest), np.broadcast_to(rest, (2, V, 3)), rtol=0, atol=1e-12)


def test_skin_is_the_weighted_blend_of_rigid_transforms():
    rng = np.random.default_rng(3)
    rest, m = _random_motion(rng, 20, 3, 2, 4)
    R = rodrigues(m.rotvec)
    want = np.zeros((4, 20, 3))
    for k in range(2):
        b = m.index[:, k]
        p = np.einsum("fvij,vj->fvi", R[:, b], rest - m.pivot[b]) + m.pivot[b] + m.translation[:, b]
        want += m.weight[None, :, k, None] * p
    np.testing.assert_allclose(skin(m, rest), want, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 30), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_unwrapped_rotations_are_the_same_rotations_without_branch_jumps(F, B, seed):
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 0.15, (F, B, 3))
    smooth = np.cumsum(steps, axis=0) + rng.normal(0.0, 2.0, (1, B, 3))  # angles beyond pi too
    theta = np.linalg.norm(smooth, axis=-1, keepdims=True)
    shift = rng.integers(-2, 3, (F, B, 1)).astype(np.float64)
    shift[0] = 0  # the first frame is kept as given
    jumpy = smooth + 2.0 * np.pi * shift * smooth / theta  # the same rotations on other branches
    got = unwrap_rotvec(jumpy)
    np.testing.assert_allclose(rodrigues(got), rodrigues(smooth), atol=1e-9)
    np.testing.assert_allclose(got, smooth, atol=1e-9)


def test_unwrap_crosses_the_identity_and_pi():
    angle = np.linspace(0.0, 4.0 * np.pi, 41)  # a full spin and more about one axis
    r = np.zeros((41, 1, 3))
    r[:, 0, 2] = np.mod(angle + np.pi, 2 * np.pi) - np.pi  # what a decomposition gives: angles in (-pi, pi]
    np.testing.assert_allclose(unwrap_rotvec(r)[:, 0, 2], angle, atol=1e-12)


@settings(max_examples=10, deadline=None)
@given(st.integers(3, 7), st.integers(1, 3), st.integers(1, 4), st.booleans(), st.integers(0, 2**32 - 1))
def test_encode_decode_round_trip_is_within_half_a_step_at_every_frame(F, B, K, looping, seed):
    """A tiny target puts a knot at every frame: every time model then returns its knots there, so the
    decoded channels differ from the (unwrapped) frames by the rounding alone (a looping motion ends where it
    starts)."""
    rng = np.random.default_rng(seed)
    rest, m = _random_motion(rng, 12, B, K, F)
    if looping:
        m.rotvec[-1], m.translation[-1] = m.rotvec[0], m.translation[0]
    times = np.cumsum(rng.uniform(0.5, 1.5, F))
    enc = encode_bones(m, times, 1e-9, rest, looping=looping)
    header, arrays = bones_header_arrays(enc)
    blob = container.pack({**HEADER, **header}, arrays, {n: container.SMALLEST for n in arrays})
    dec = decode_bones(*container.unpack(blob), n_vertices=12)
    for name in ("segment_t", "pivot", "index", "weight_q", "time_model", "mu", "step", "codes"):
        np.testing.assert_array_equal(getattr(dec, name), getattr(enc, name), err_msg=name)
    assert dec.n_segments == F - 1
    t = (times - times[0]) / (times[-1] - times[0])
    want = np.concatenate([unwrap_rotvec(m.rotvec), m.translation], axis=2)
    got = BoneTracks(dec, looping).channels(t)
    if looping:  # t = 1 wraps to the first frame: the same pose, its rotation maybe on another branch
        np.testing.assert_allclose(rodrigues(got[-1, :, :3]), rodrigues(want[-1, :, :3]), atol=1e-6)
        got, want = got[:-1], want[:-1]
    half = dec.step.astype(np.float64)[None] / 2
    assert np.all(np.abs(got - want) <= half * (1 + 1e-6) + 1e-12)


def test_encode_meets_its_target_on_a_bending_tube_and_chooses_time_models_per_channel():
    rest, _, motion = bend_motion(33, 4, 3)
    times = np.arange(33) / 30.0
    diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
    truth = skin(motion, rest)
    t = (times - times[0]) / (times[-1] - times[0])
    sizes = []
    for rel in (3e-3, 1e-3):
        enc = encode_bones(motion, times, rel * diag, rest.astype(np.float32))
        d = np.linalg.norm(skinned_positions(enc, rest, t) - truth, axis=2)
        assert np.sqrt((d**2).mean()) <= rel * diag and enc.report["met"], enc.report
        assert 1 <= enc.n_segments < 32  # far fewer segments than frames: the time models carry the motion
        assert set(np.unique(enc.time_model)) <= {0, 1}
        assert np.all(enc.mu[:, enc.time_model == TIME_SPLINE] == 0)
        assert np.all(enc.mu > -np.pi)
        np.testing.assert_array_equal(coarse_mu(enc.mu), enc.mu)  # few significant bits: cheap to store
        sizes.append(enc.n_segments)
    assert sizes[0] <= sizes[1]


def test_a_still_and_unused_bones_encode():
    rest, m = _random_motion(np.random.default_rng(5), 10, 3, 1, 1)
    index = np.zeros_like(m.index)  # bones 1 and 2 move no vertex
    m = BoneMotion(m.pivot, index, np.ones_like(m.weight), m.rotvec, m.translation)
    enc = encode_bones(m, np.array([0.0]), 1e-4, rest)
    np.testing.assert_array_equal(enc.segment_t, [0.0, 1.0])
    got = skinned_positions(enc, rest, np.array([0.0, 1.0]))
    assert np.abs(got - skin(m, rest)[0]).max() < 1e-3


@settings(max_examples=40, deadline=None)
@given(st.floats(-3.0, 40.0), st.integers(1, 8))
def test_coarse_time_constants_keep_a_few_bits_towards_zero(mu, bits):
    got = float(coarse_mu(np.array([mu]), bits)[0])
    assert abs(got) <= abs(mu) and np.sign(got) in (0.0, np.sign(mu))
    assert abs(mu - got) <= abs(mu) * 2.0 ** (1 - bits)
    mantissa, _ = np.frexp(abs(got))
    assert float(mantissa * 2**bits) == int(mantissa * 2**bits)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 30), st.integers(1, 4), st.integers(1, 16), st.integers(0, 2**32 - 1))
def test_weight_levels_sum_to_the_scale_and_stay_within_one_level(V, K, bits, seed):
    rng = np.random.default_rng(seed)
    w = rng.uniform(0.0, 1.0, (V, K)) ** 3 + 1e-9
    w /= w.sum(axis=1, keepdims=True)
    scale = 2**bits - 1
    q = weight_levels(w, scale)
    assert np.all(q.sum(axis=1) == scale) and np.all(q >= 0)
    assert np.all(np.abs(q - w * scale) < 1.0)


def test_sorted_influences_merge_repeats_and_put_zero_weights_last():
    index = np.array([[3, 1, 3, 0], [2, 2, 5, 1], [4, 0, 1, 2]])
    q = np.array([[10, 5, 7, 0], [1, 2, 0, 12], [0, 6, 0, 9]])
    got_i, got_q = sorted_influences(index, q)
    np.testing.assert_array_equal(got_i, [[1, 3, 3, 3], [1, 2, 2, 2], [0, 2, 2, 2]])
    np.testing.assert_array_equal(got_q, [[5, 17, 0, 0], [12, 3, 0, 0], [6, 9, 0, 0]])


def _stored(K: int = 2, B: int = 3, V: int = 8) -> tuple[dict, dict]:
    enc = synthetic_bones(V, B, K, seed=1)
    header, arrays = bones_header_arrays(enc)
    return {**HEADER, **header}, arrays


def _with(arrays: dict, name: str, value: np.ndarray) -> dict:
    return {**arrays, name: value}


def _row_over(weight: np.ndarray) -> np.ndarray:
    """The stored weights with row 2 above the 12-bit scale of the synthetic layer."""
    out = weight.copy()
    out[2] = 5000
    return out


REJECTIONS = [
    ("missing array", lambda h, a: (h, {k: v for k, v in a.items() if k != "bone_weight"}),
     "no 'bone_weight'"),
    ("dtype", lambda h, a: (h, _with(a, "bone_index", a["bone_index"].astype(np.uint32))), "dtype"),
    ("shape", lambda h, a: (h, _with(a, "bone_step", a["bone_step"][:, :5])), "shape"),
    ("no bones", lambda h, a: ({**h, "n_bones": 0}, a), "n_bones"),
    ("K 5", lambda h, a: ({**h, "bone_influences": 5}, a), "bone_influences"),
    ("K 0", lambda h, a: ({**h, "bone_influences": 0}, a), "bone_influences"),
    ("differences", lambda h, a: ({**h, "bone_knot_differences": 3}, a), "bone_knot_differences"),
    ("index >= B", lambda h, a: (h, _with(a, "bone_index", np.full_like(a["bone_index"], 3))),
     "below n_bones"),
    ("weights over the scale", lambda h, a: (h, _with(a, "bone_weight", _row_over(a["bone_weight"]))),
     "sum above 2\\^bone_weight_bits - 1 \\(4095\\)"),
    ("weight bits 0", lambda h, a: ({**h, "bone_weight_bits": 0}, a), "bone_weight_bits"),
    ("weight bits 17", lambda h, a: ({**h, "bone_weight_bits": 17}, a), "bone_weight_bits"),
    ("weight bits missing", lambda h, a: ({k: v for k, v in h.items() if k != "bone_weight_bits"}, a),
     "bone_weight_bits"),
    ("weights K columns", lambda h, a: (h, _with(a, "bone_weight", np.ones((8, 2), np.uint16))), "shape"),
    ("step 0", lambda h, a: (h, _with(a, "bone_step", np.zeros_like(a["bone_step"]))), "positive"),
    ("step nan", lambda h, a: (h, _with(a, "bone_step", np.full_like(a["bone_step"], np.nan))), "non-finite"),
    ("mu -pi", lambda h, a: (h, _with(a, "bone_m", np.full_like(a["bone_m"], -np.float32(np.pi)))),
     "above -pi"),
    ("spline mu", lambda h, a: (h, _with(a, "bone_m", np.full_like(a["bone_m"], 0.5))), "time constant 0"),
    ("time model 2", lambda h, a: (h, _with(a, "bone_time_model", np.full_like(a["bone_time_model"], 2))),
     "0 \\(paper pair\\) or 1"),
    ("pivot inf", lambda h, a: (h, _with(a, "bone_pivot", np.full_like(a["bone_pivot"], np.inf))),
     "non-finite"),
    ("knots overflow", lambda h, a: (h, _with(a, "bone_step", np.full_like(a["bone_step"], 3e38))),
     "non-finite"),
    ("segments", lambda h, a: (h, _with(a, "bone_segment_t", np.array([0.0, 0.7, 0.6, 1.0]))), "increase"),
    ("segment end", lambda h, a: (h, _with(a, "bone_segment_t", np.array([0.0, 0.2, 0.6, 0.9]))), "increase"),
    ("rigid", lambda h, a: ({**h, "motion": "rigid"}, a), "motion 'displacement'"),
    ("absolute", lambda h, a: ({**h, "motion": "absolute"}, a), "motion 'displacement'"),
]


@pytest.mark.parametrize("name,edit,message", REJECTIONS, ids=[r[0] for r in REJECTIONS])
def test_reader_rejections(name, edit, message):
    header, arrays = edit(*_stored())
    with pytest.raises(ClipFormatError, match=message):
        decode_bones(header, arrays, n_vertices=8)


def test_reader_rejects_a_vertex_count_other_than_the_topology():
    with pytest.raises(ClipFormatError, match="shape"):
        decode_bones(*_stored(), n_vertices=9)


def _bone_clip(tmp_path, residual: bool):
    """A fitted tube clip with an encode_bones layer (tests.conformance.bonecases)."""
    from tests.conformance.bonecases import fitted_bone_case

    parts = fitted_bone_case(2, 3, residual=residual)()
    path = tmp_path / "bones.clip"
    write_clip_file(path, parts)
    return parts, path


def test_a_clip_with_bones_is_format_1_1_and_evaluates_skin_then_residual(tmp_path):
    parts, path = _bone_clip(tmp_path, residual=True)
    file_header = container.unpack(path.read_bytes())[0]
    assert file_header["format_version"] == "1.1" and file_header["required"] == ["bones"]
    coef_header, coef_arrays = container.unpack(parts.coefficients)
    assert coef_header["format_version"] == "1.1" and coef_header["required"] == ["bones"]
    assert container.unpack(parts.topology)[0]["format_version"] == "1.0"
    clip = load_clip(*(lambda p: (p.topology, p.coefficients))(read_clip_file(path)))
    t = np.array([0.0, 0.13, 0.5, 0.77, 1.0])
    base = skinned_positions(clip.coef.bones, clip.topo.rest, t)
    plain = load_clip(parts.topology, container.pack(
        {k: v for k, v in coef_header.items() if k not in ("required",)} | {"format_version": "1.0"},
        {k: v for k, v in coef_arrays.items() if not k.startswith("bone_")}))
    residual = plain.evaluate(t) - clip.topo.rest  # the curves alone, as a displacement
    assert np.abs(residual).max() > 1e-3  # the residual is not zero here
    # §3.8 with base = the skinned positions: (phi0 P_s + phi1 P_s+1) + base in float32
    np.testing.assert_allclose(clip.evaluate(t), base + residual, rtol=0, atol=2e-6)
    assert clip.info()["bones"] == {"n_bones": 3, "influences": 2, "segments": clip.coef.bones.n_segments}
    for s in (0.0, 0.42, 1.0):  # the scalar fast path agrees with the array path
        np.testing.assert_array_equal(clip.evaluate(s), clip.evaluate(np.array([s]))[0])


def test_a_clip_without_bones_is_written_as_before(tmp_path):
    from tests.conformance.generate import CASES

    parts = CASES["fit-displacement-chord"][0]()
    write_clip_file(tmp_path / "plain.clip", parts)
    header = container.unpack((tmp_path / "plain.clip").read_bytes())[0]
    assert header["format_version"] == "1.0" and "required" not in header
    assert "required" not in container.unpack(parts.coefficients)[0]


def test_bones_go_only_on_displacement_clips():
    from tests.conformance.generate import CASES

    parts = CASES["fit-rigid-chord"][0]()
    with pytest.raises(Exception, match="motion 'displacement'"):
        repack_with_bone_layer(parts.coefficients, synthetic_bones(10, 2, 2, seed=3))


def test_cli_frame_evaluates_a_clip_with_bones(tmp_path):
    from pdeanim.gltf.validate import assert_clean, validate_many
    from pdeanim_service.cli import main

    parts, path = _bone_clip(tmp_path, residual=False)
    clip = load_clip(parts.topology, parts.coefficients)
    assert main(["frame", str(path), "--t", "0,0.3,1", "--out", str(tmp_path / "f.npz")]) == 0
    got = np.load(tmp_path / "f.npz")["vertices"]
    want = skinned_positions(clip.coef.bones, clip.topo.rest, np.array([0.0, 0.3, 1.0]))
    np.testing.assert_array_equal(got, want)  # zero residual: the skinned positions exactly
    assert main(["frame", str(path), "--t", "0.3", "--out", str(tmp_path / "f.glb")]) == 0
    assert_clean(validate_many([(tmp_path / "f.glb").read_bytes()])[0], "frame of a clip with bones")


def test_cli_refuses_a_clip_that_requires_an_unknown_feature(tmp_path, capsys):
    from pdeanim_service.cli import main
    from tests.conformance.bonecases import UNKNOWN_FEATURE, unknown_feature_case

    write_clip_file(tmp_path / "future.clip", unknown_feature_case())
    assert main(["frame", str(tmp_path / "future.clip"), "--t", "0.5", "--out", str(tmp_path / "f.npz")]) == 2
    err = capsys.readouterr().err
    assert UNKNOWN_FEATURE in err and "supports: bones" in err


def test_compiled_and_numpy_skinning_agree_bit_for_bit(monkeypatch):
    from pdeanim.model import bonelayer

    rng = np.random.default_rng(9)
    enc = synthetic_bones(200, 5, 4, seed=7)
    player = bonelayer.BonePlayer(enc, rng.normal(0.0, 1.0, (200, 3)))
    t = np.linspace(-0.1, 1.1, 7)
    compiled = player.positions(t)
    monkeypatch.setattr(bonelayer, "COMPILED", False)
    np.testing.assert_array_equal(player.positions(t), compiled)


def test_weak_influences_are_dropped_within_the_budget():
    rest, _, motion = bend_motion(17, 5, 4)
    times = np.arange(17) / 24.0
    diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
    w = np.array(motion.weight)
    w[:, -1] = np.where(w[:, -1] > 0, 1e-3, 0.0)  # a negligible last influence on every vertex
    w /= w.sum(axis=1, keepdims=True)
    weak = BoneMotion(motion.pivot, motion.index, w, motion.rotvec, motion.translation)
    target = 1e-3 * diag
    enc = encode_bones(weak, times, target, rest)
    assert np.count_nonzero(enc.weight_q == 0) >= len(rest)  # at least the negligible influence went
    t = (times - times[0]) / (times[-1] - times[0])
    d = np.linalg.norm(skinned_positions(enc, rest, t).astype(np.float64) - skin(weak, rest), axis=-1)
    assert np.sqrt(np.mean(d * d)) <= target
