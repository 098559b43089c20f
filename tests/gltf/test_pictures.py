"""Error pictures: PNGs of a mesh coloured by per-vertex error and of error per frame; simplification of
big meshes before drawing keeps hot spots and leaves no degenerate faces."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from pdeanim.errors import ParameterError
from pdeanim.pictures import (
    error_curve_png,
    error_png,
    fit_error_pictures,
    principal_frame,
    simplify_for_picture,
)


def colours(path) -> int:
    with Image.open(path) as im:
        assert im.format == "PNG"
        return len(np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0))


def test_error_png_of_spot(spot, tmp_path):
    v, f = spot
    err = np.linalg.norm(v - v.mean(axis=0), axis=1)
    path = error_png(v, f, err, tmp_path / "spot.png", "spot", units="m")
    with Image.open(path) as im:
        assert im.size == (1100, 484)
    assert colours(path) > 200  # a shaded colour ramp, not a blank canvas


def test_simplify_keeps_hot_spots_and_valid_faces(spot):
    v, f = spot
    err = np.zeros(len(v))
    err[123] = 7.0
    sv, sf, se = simplify_for_picture(v.astype(np.float64), f, err, limit=1500)
    assert 0 < len(sf) <= 1500 and se.max() == 7.0
    assert np.all((sf[:, 0] != sf[:, 1]) & (sf[:, 1] != sf[:, 2]) & (sf[:, 0] != sf[:, 2]))
    assert sf.max() < len(sv) and np.ptp(sv, axis=0) == pytest.approx(np.ptp(v, axis=0), rel=0.1)
    same = simplify_for_picture(v, f, err, limit=len(f))
    assert same[1] is f


def test_principal_frame_is_a_rotation(spot):
    v, _ = spot
    _, axes = principal_frame(v)
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(axes) == pytest.approx(1.0)
    spread = np.var((v - v.mean(axis=0)) @ axes.T, axis=0)
    assert spread[0] >= spread[1] >= spread[2]


def test_fit_error_pictures_and_curve(morph, tmp_path):
    frames, faces, times = morph
    fitted = frames.copy()
    fitted[50, :10] += 0.05  # the worst frame
    paths = fit_error_pictures(frames, fitted, faces, times, tmp_path, "morph")
    assert paths["worst_frame"].name == "morph_worst_frame.png" and colours(paths["worst_frame"]) > 50
    assert colours(paths["error_curve"]) > 20
    with Image.open(paths["worst_frame"]) as im:  # the frame drawn is the one with the largest max error
        assert im.text["Title"] == f"morph: per-vertex error at frame 50 (t = {times[50]:.3f} s)"
        assert im.text["Description"].startswith(f"max {np.sqrt(3) * 0.05:.3g}")
    with Image.open(paths["error_curve"]) as im:
        assert im.text["Description"] == "worst frame 50"
    with pytest.raises(ParameterError):
        error_curve_png(np.ones(3), np.ones(4), np.arange(3), tmp_path / "x.png")
    with pytest.raises(ParameterError):
        error_png(frames[0], faces, np.ones(5), tmp_path / "y.png", "bad")
    with pytest.raises(ParameterError):
        error_png(frames[0], None, np.ones(len(frames[0])), tmp_path / "z.png", "points")
