"""The spatial floor: exactness where the basis suffices, Kabsch, and the ordering of motion variants."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.curves import extract_curves
from pdeanim.curves.deform import bend_twist
from pdeanim.curves.floor import kabsch_residual, rigid_motions, spatial_floor
from pdeanim.curves.naive import greedy_edge_curves
from pdeanim.curveset import CurveSet
from pdeanim.errors import InputError, ParameterError


def random_rotations(rng, n):
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


@pytest.fixture(scope="module")
def spot_curves(spot):
    v, f = spot
    return v, extract_curves(v, f)


def test_short_curves_are_exact():
    rng = np.random.default_rng(0)
    frames = rng.standard_normal((5, 12, 3))
    cs = CurveSet.from_lists([[0, 1, 2, 3], [4, 5], [6], [7, 8, 9, 10, 11][:4], [11]])
    for motion in ("absolute", "displacement", "rigid"):
        assert spatial_floor(frames, cs, motion).rms < 1e-9


def test_rigid_motion_per_curve_has_zero_rigid_floor(spot_curves):
    v, cs = spot_curves
    rng = np.random.default_rng(1)
    rot = random_rotations(rng, cs.n_curves * 4).reshape(4, cs.n_curves, 3, 3)
    shift = rng.standard_normal((4, cs.n_curves, 3))
    cid, _ = cs.curve_of_vertex(len(v))
    frames = np.concatenate([v[None], np.einsum("vi,fvji->fvj", v, rot[:, cid]) + shift[:, cid]])
    rigid = spatial_floor(frames, cs, "rigid")
    disp = spatial_floor(frames, cs, "displacement")
    assert rigid.rel_rms < 1e-9 and rigid.rel_max < 1e-8
    assert disp.rel_rms > 1e-4


def test_translation_has_zero_displacement_floor(spot_curves):
    v, cs = spot_curves
    frames = v[None] + np.linspace(0, 1, 5)[:, None, None] * np.array([1.0, -2.0, 0.5])
    assert spatial_floor(frames, cs, "displacement").rms < 1e-9
    assert spatial_floor(frames, cs, "absolute").rms > 0


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 12))
def test_kabsch_recovers_random_rigid_motion(seed, n):
    rng = np.random.default_rng(seed)
    rest = rng.standard_normal((2, n, 3))
    rot = random_rotations(rng, 6).reshape(3, 2, 3, 3)
    frames = np.einsum("cni,fcji->fcnj", rest, rot) + rng.standard_normal((3, 2, 1, 3))
    res = kabsch_residual(rest, frames, np.ones((2, n), bool))
    assert np.abs(res).max() < 1e-9
    r, _ = rigid_motions(rest, frames, np.ones((2, n), bool))
    assert np.allclose(r, np.swapaxes(rot, -1, -2), atol=1e-9)  # frames use rot @ x, i.e. x @ rot.T


def test_floor_decreases_absolute_displacement_rigid_on_morph_sphere(morph):
    x, f = morph
    cs = extract_curves(x[0], f)
    a, d, r = (spatial_floor(x, cs, m) for m in ("absolute", "displacement", "rigid"))
    assert a.rel_rms > d.rel_rms > r.rel_rms > 0


def test_smooth_curves_beat_greedy_paths_on_bent_bob(bob):
    v, f = bob
    frames = bend_twist(v, 12)
    smooth = extract_curves(v, f, target_points=10)
    naive = greedy_edge_curves(v, f, target_points=10)
    assert smooth.lengths.mean() > naive.lengths.mean()  # fewer, longer curves ...
    for motion in ("absolute", "displacement", "rigid"):  # ... and still a lower floor
        assert spatial_floor(frames, smooth, motion).rms < spatial_floor(frames, naive, motion).rms
    r = spatial_floor(frames, smooth, "rigid")
    assert r.per_curve_rms.shape == (smooth.n_curves,) and r.rel_rms < 1e-3


def test_floor_rejects_bad_input(spot_curves):
    v, cs = spot_curves
    with pytest.raises(ParameterError):
        spatial_floor(v[None], cs, "sideways")
    with pytest.raises(InputError):
        spatial_floor(v[None, :-1], cs, "absolute")
