"""Fits in windows of frames (pdeanim.fit.windowed): the joined clip is one clip, continuous across window
bounds (each window's first and last frames are knots, a linear segment joins two windows), whose windows
choose their segments and rounding as a one-piece fit does; it meets its target, stores what its report says,
and matches the one-piece fit of the same frames within the target whatever the window size."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.fit import FitOptions, FitTolerances, fit_poses
from pdeanim.model.clipformat import ClipFormatError, decode_coefficients
from pdeanim.poses import Poses, make_poses

TARGET = 3e-3


def _motion(frames: int, seed: int) -> Poses:
    """An icosphere bending, twisting and travelling smoothly (random phases)."""
    rng = np.random.default_rng(seed)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    x = np.asarray(mesh.vertices)[None]
    t = np.linspace(0.0, 1.0, frames)[:, None, None]
    ph = rng.uniform(0, 2 * np.pi, 3)
    bend = 0.3 * np.sin(2 * np.pi * (1.5 * t + x[..., :1]) + ph[0]) * np.array([0.0, 0.0, 1.0])
    twist = 0.2 * np.sin(2 * np.pi * t + ph[1]) * x[..., [1, 0, 2]] * np.array([1.0, -1.0, 0.0])
    travel = np.array([1.0, 0.0, 0.0]) * np.sin(np.pi * t + ph[2])
    return make_poses((x + bend + twist + travel).astype(np.float32), np.asarray(mesh.faces))


def _windowed(window_frames: int, V: int) -> FitTolerances:
    return FitTolerances(window_fit_values=0, window_values=window_frames * V)


def _decoded_rms(parts, poses: Poses) -> float:
    clip = load_clip(parts.topology, parts.coefficients)
    d = np.linalg.norm(clip.evaluate(clip.frame_t()).astype(np.float64) - poses.vertices, axis=-1)
    return float(np.sqrt(np.mean(d * d)))


@pytest.fixture(scope="module")
def motion() -> Poses:
    return _motion(60, 0)


def test_a_windowed_fit_is_one_clip_that_meets_its_target_and_stores_what_it_reports(motion):
    parts = fit_poses(motion, FitOptions(target_rel_rms=TARGET), tolerances=_windowed(8, motion.n_vertices))
    r = parts.report
    assert r["windowed"] and r["target_met"]
    assert [w["frames"] for w in r["windows"]][:2] == [[0, 9], [9, 17]]  # 7 balanced windows of 8-9 frames
    assert 0.8 * TARGET <= r["rel_rms"] <= TARGET and r["rel_max"] <= 3.0 * TARGET
    assert _decoded_rms(parts, motion) == pytest.approx(r["rms"], rel=1e-6)
    # every window's first and last frames are knots: the windows meet at a segment between two frames
    for f0, f1 in (w["frames"] for w in r["windows"]):
        assert f0 in r["segment_frames"] and f1 - 1 in r["segment_frames"]
    # continuity across windows: halfway between two frames on either side of a window boundary the clip lies
    # between its neighbours' positions (no jump where a window ends)
    clip = load_clip(parts.topology, parts.coefficients)
    t = clip.frame_t()
    mid = clip.evaluate(0.5 * (t[8] + t[9])).astype(np.float64)
    ends = clip.evaluate(t[[8, 9]]).astype(np.float64)
    assert np.abs(mid - ends.mean(axis=0)).max() <= np.abs(ends[1] - ends[0]).max() + 1e-6


def test_windows_of_smooth_motion_put_knots_where_the_motion_needs_them():
    """A slow, smooth motion in two windows: each window keeps far fewer knots than frames (as the one-piece
    fit of the same frames does), the clip meets its target as decoded (max within 3x), and the same input
    gives the same bytes twice (every step deterministic)."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    x = np.asarray(mesh.vertices)[None]
    t = np.linspace(0.0, 1.0, 80)[:, None, None]
    poses = make_poses((x * (1.0 + 0.2 * np.sin(np.pi * t) * x[..., 2:]) + 0.5 * t * t).astype(np.float32),
                       np.asarray(mesh.faces))
    tol = _windowed(40, poses.n_vertices)
    parts = fit_poses(poses, FitOptions(target_rel_rms=TARGET), tolerances=tol)
    r = parts.report
    assert len(r["windows"]) == 2 and r["segments"] <= 30, r["segments"]
    assert all(w["segments"] < 20 for w in r["windows"]), r["windows"]
    clip = load_clip(parts.topology, parts.coefficients)
    d = np.linalg.norm(clip.evaluate(clip.frame_t()).astype(np.float64) - poses.vertices, axis=-1)
    assert np.sqrt(np.mean(d * d)) <= TARGET * r["diagonal"] and d.max() <= 3.0 * TARGET * r["diagonal"]
    again = fit_poses(poses, FitOptions(target_rel_rms=TARGET), tolerances=tol)
    assert (again.topology, again.coefficients) == (parts.topology, parts.coefficients)


def test_windows_past_the_search_bound_store_the_dense_candidate(motion):
    """FitTolerances.window_search_values bounds the search's cost: a window of more frame-vertex values
    skips the error-driven search and keeps a knot at every frame, still meeting its target as decoded."""
    tol = replace(_windowed(30, motion.n_vertices), window_search_values=0)
    parts = fit_poses(motion, FitOptions(target_rel_rms=TARGET), tolerances=tol)
    r = parts.report
    assert len(r["windows"]) == 2 and r["segments"] == motion.n_frames - 1, r["segments"]
    assert r["target_met"] and _decoded_rms(parts, motion) <= TARGET * r["diagonal"]


def test_the_steps_through_bytes_give_the_clip_of_the_in_process_fit(motion):
    """Every step's result through to_bytes/from_bytes (what window tasks store) joins to the very clip of
    the in-process windowed fit, including windows whose knots are on their own shared time basis."""
    from pdeanim.fit import windowed

    tol = _windowed(20, motion.n_vertices)
    options = FitOptions(target_rel_rms=TARGET)
    whole = fit_poses(motion, options, tolerances=tol)
    plan = windowed.WindowPlan.from_bytes(windowed.plan_windows(motion, options, tol).to_bytes())
    frames = [motion.vertices[slice(*plan.window(i))] for i in range(plan.n_windows)]
    grams = [windowed.GramPart.from_bytes(windowed.gram_window(plan, f, i).to_bytes())
             for i, f in enumerate(frames)]
    space = windowed.SpaceModel.from_bytes(windowed.join_space(plan, grams).to_bytes())
    model = windowed.WindowModel(plan, space)
    codes = [windowed.WindowCodes.from_bytes(windowed.encode_window(model, f, i).to_bytes())
             for i, f in enumerate(frames)]
    parts = windowed.join_clip(plan, space, codes)
    assert (parts.topology, parts.coefficients) == (whole.topology, whole.coefficients)
    h, _ = container.unpack(whole.coefficients)
    if h["knot_rank"]:  # the windows' bases side by side decode to what each window measured
        assert _decoded_rms(whole, motion) == pytest.approx(whole.report["rms"], rel=1e-6)


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10**6), window=st.integers(8, 25))
def test_windowed_and_one_piece_fits_agree_within_the_target(seed, window):
    """Any window size: the windowed clip meets the target and its frames lie within twice the target (RMS)
    of the one-piece fit's (each is within the target of the data; measured 1.24-1.28x). Bytes: this motion
    is low-rank, which the one-piece fit stores on one shared time basis and the windowed one on a basis per
    window, on the finest of the windows' steps (measured up to 1.63x for 5 windows of 8 frames, where the
    per-window overheads weigh most)."""
    poses = _motion(40, seed)
    whole = fit_poses(poses, FitOptions(target_rel_rms=TARGET), tolerances=FitTolerances(dense_fit=True))
    part = fit_poses(poses, FitOptions(target_rel_rms=TARGET), tolerances=_windowed(window, poses.n_vertices))
    assert part.report["windowed"] and part.report["target_met"]
    a, b = (load_clip(p.topology, p.coefficients) for p in (whole, part))
    d = np.linalg.norm(a.evaluate(a.frame_t()).astype(np.float64) - b.evaluate(b.frame_t()), axis=-1)
    assert np.sqrt(np.mean(d * d)) <= 2 * TARGET * whole.report["diagonal"]
    size = [len(p.topology) + len(p.coefficients) for p in (whole, part)]
    assert size[1] <= 2.5 * size[0]


def test_every_window_meets_the_target_alone_and_small_windows_cost_few_bytes(motion):
    """Each window's rate control is its own (knot steps per window): each meets the target; small windows
    cost more than one window: their steps, their end knots, no trading of error between windows, and no
    segments longer than a window (measured 1.56x for 7 windows of 8 frames of a 162-vertex mesh against one
    window of 60 frames that needs 7 segments)."""
    small = fit_poses(motion, FitOptions(target_rel_rms=TARGET), tolerances=_windowed(8, motion.n_vertices))
    large = fit_poses(motion, FitOptions(target_rel_rms=TARGET), tolerances=_windowed(60, motion.n_vertices))
    target = TARGET * small.report["diagonal"]
    assert len(small.report["windows"]) == 7 and len(large.report["windows"]) == 1
    assert all(0.6 * target <= w["rms"] <= target for w in small.report["windows"])
    assert len(small.coefficients) <= 2.0 * len(large.coefficients)


def test_broken_knot_windows_raise_clear_errors(motion):
    """docs/format.md §3.4: knot_windows rise strictly from 0 to S+1, one knot step per window, no basis."""
    tol = replace(_windowed(20, motion.n_vertices), knot_basis=False)
    parts = fit_poses(motion, FitOptions(target_rel_rms=TARGET), tolerances=tol)
    h, a = container.unpack(parts.coefficients)
    S, C = h["n_segments"], h["n_curves"]
    windows = a["knot_windows"]
    assert len(windows) == 4 and windows[0] == 0 and windows[-1] == S + 1
    assert a["knot_step"].shape == (3, C, 3)
    w1, w2 = int(windows[1]), int(windows[2])

    def edit(header: dict | None = None, drop: str | None = None, **arrays) -> bytes:
        b = {k: v for k, v in {**a, **arrays}.items() if k != drop}
        return container.pack({**h, **(header or {})}, b)

    cases = [
        (edit(knot_windows=np.array([0, w2, w1, S + 1], np.uint32)), f"must rise strictly from 0 to {S + 1}"),
        (edit(knot_windows=np.array([1, w1, w2, S + 1], np.uint32)), "must rise strictly"),
        (edit(knot_windows=np.array([0, w1, w2, S], np.uint32)), "must rise strictly"),
        (edit(knot_windows=windows.astype(np.int32)), "'knot_windows' has dtype"),
        (edit(knot_windows=windows[:-1]), "'knot_step' has shape"),
        (edit(drop="knot_windows"), "'knot_step' has shape"),
        (edit(knot_step=a["knot_step"][0]), "'knot_step' has shape"),
        (edit({"knot_rank": 1}, knot_weights=np.zeros((1, C, 3, 4), np.uint32),
              knot_basis=np.zeros((1, S + 1), np.float32)), "need knot_rank 0"),
    ]
    for broken, match in cases:
        with pytest.raises(ClipFormatError, match=match):
            decode_coefficients(*container.unpack(broken), C)


def test_windows_of_a_low_rank_motion_share_one_set_of_knot_weights():
    """A blend of two shapes in 3 windows: every window puts its knots on the clip's shared weights (the
    principal shapes of the plan's frames), stored once: the clip's rank is that of one window, not the sum,
    it decodes to what the windows measured, and it is smaller than with a basis per window."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    x = np.asarray(mesh.vertices)
    t = np.linspace(0.0, 1.0, 60)[:, None, None]
    shapes = 0.3 * np.sin(3 * x[None]) * np.array([1.0, 0.5, -0.7]), 0.2 * x[None, :, [1, 2, 0]] ** 2
    frames = x[None] + np.sin(2 * np.pi * t) * shapes[0] + np.cos(3 * np.pi * t) ** 2 * shapes[1]
    poses = make_poses(frames.astype(np.float32), np.asarray(mesh.faces))
    options, tol = FitOptions(target_rel_rms=TARGET), _windowed(20, poses.n_vertices)
    shared = fit_poses(poses, options, tolerances=tol)
    own = fit_poses(poses, options, tolerances=replace(tol, window_shared_weights=False))
    windows = shared.report["windows"]
    assert len(windows) == 3 and all(w["shared_weights"] for w in windows), windows
    assert shared.report["knot_rank"] == max(w["knot_rank"] for w in windows) > 0
    assert shared.report["target_met"]
    assert _decoded_rms(shared, poses) == pytest.approx(shared.report["rms"], rel=1e-6)
    size = [len(p.topology) + len(p.coefficients) for p in (shared, own)]
    assert size[0] < 0.9 * size[1], size


@pytest.mark.parametrize("compressed", [False, True])
def test_poses_mapped_from_a_file_give_the_clip_of_poses_in_memory(motion, tmp_path, compressed):
    """A long .npz read a window at a time from a file mapping (the CLI's path for windowed fits: the .npz
    itself when stored uncompressed, else a temporary file it is inflated into) fits the very same clip."""
    from pdeanim.npzread import release_pages
    from pdeanim.posefiles import load_poses

    path = tmp_path / "poses.npz"
    (np.savez_compressed if compressed else np.savez)(path, vertices=motion.vertices, faces=motion.faces)
    mapped = load_poses(path, map_over=0)
    assert isinstance(mapped.vertices, np.memmap) and np.array_equal(mapped.vertices, motion.vertices)
    release_pages(mapped.vertices)  # dropped pages read back the same
    assert np.array_equal(mapped.vertices[5], motion.vertices[5])
    tol, options = _windowed(20, motion.n_vertices), FitOptions(target_rel_rms=TARGET)
    parts = fit_poses(mapped, options, tolerances=tol)
    whole = fit_poses(motion, options, tolerances=tol)
    assert (parts.topology, parts.coefficients) == (whole.topology, whole.coefficients)
    bad = motion.vertices.copy()
    bad[7, 3, 1] = np.inf
    (np.savez_compressed if compressed else np.savez)(path, vertices=bad, faces=motion.faces)
    with pytest.raises(Exception, match="frame 7, vertex 3"):
        load_poses(path, map_over=0)
