"""Motion mode "rigid": Kabsch per curve, rotation tracks, residual in the moving frame, evaluation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pdeanim.clip import load_clip
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model.metrics import error_summary
from pdeanim.model.rigid import continuous_rotvec, kabsch, rodrigues
from pdeanim.model.simplecurves import simple_curves
from pdeanim.poses import make_poses


def test_rodrigues_matches_scipy(rng):
    r = rng.normal(size=(20, 3)) * np.array([[1.0]] * 10 + [[1e-6]] * 10)
    np.testing.assert_allclose(rodrigues(r), Rotation.from_rotvec(r).as_matrix(), atol=1e-12)


def test_kabsch_recovers_rotation_and_rotvec_is_continuous(rng):
    rest = rng.normal(size=(4, 9, 3))
    mask = np.ones((4, 9), bool)
    mask[1, 6:] = False
    ang = np.linspace(0, 5.0, 30)  # past pi: the unwrapped rotation vector keeps growing
    R = rodrigues(np.stack([0 * ang, ang, 0 * ang], -1))
    frames = np.einsum("fij,cnj->fcni", R, rest - rest.mean(1, keepdims=True)) + 2.0
    Rk, _, _ = kabsch(rest, frames, mask)
    np.testing.assert_allclose(Rk, np.broadcast_to(R[:, None], Rk.shape), atol=1e-10)
    rv = continuous_rotvec(Rk)
    np.testing.assert_allclose(rv[:, 0, 1], ang, atol=1e-8)


def test_rigidly_moving_curves_fit_exactly(rng):
    """Curves that only rotate and translate: rigid mode leaves a far smaller error than displacement."""
    V = 240
    base = rng.normal(size=(V, 3))
    t = np.linspace(0, 1, 40)
    curves = simple_curves(base, max_points=12)
    cid, _ = curves.curve_of_vertex(V)
    frames = np.empty((40, V, 3))
    for c in range(curves.n_curves):  # test data only: each curve spins about its own centre
        sel = cid == c
        centre = base[sel].mean(0)
        R = rodrigues(np.outer(t, [0.3 * c % 1.0, 1.2, 0.2]))
        frames[:, sel] = (
            np.einsum("fij,nj->fni", R, base[sel] - centre) + centre + np.outer(t, [0.5, 0, 0])[:, None]
        )
    poses = make_poses(frames.astype(np.float32), None)
    rigid = fit_poses(poses, FitOptions(segments=2, motion="rigid"), curves=curves)
    disp = fit_poses(poses, FitOptions(segments=2, motion="displacement"), curves=curves)
    assert rigid.report["rel_rms"] < 0.2 * disp.report["rel_rms"]
    assert rigid.report["rel_rms"] < 2e-3
    clip = load_clip(rigid.topology, rigid.coefficients)
    s = error_summary(poses.vertices, clip.evaluate(clip.frame_t()))
    assert s["rms"] == pytest.approx(rigid.report["rms"], rel=1e-6)


def test_rigid_mode_on_morph_sphere(morph_small):
    curves = simple_curves(morph_small.vertices[0], max_points=6)
    parts = fit_poses(morph_small, FitOptions(target_rel_rms=5e-3, motion="rigid"), curves=curves)
    r = parts.report
    assert r["target_met"] and r["rel_rms"] <= 5e-3
    # the stored clip differs from the float64 model by its rounding: knots by at most knot_cap and the rest
    # pose by at most the tolerance per coordinate (the rigid frames turn them, keeping lengths)
    bound = np.sqrt(3) * ((r["quantisation_knot_cap"] or 0.0) + r["quantisation_tolerance"])
    assert r["float32_vs_float64_max"] <= bound * 1.01 + 1e-6 * r["diagonal"]
