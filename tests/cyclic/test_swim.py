"""The spine wave: presets, overrides, the loop property and the shape of the motion."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.cyclic.swim import ALIASES, PRESETS, SwimParams, body_displacement, lateral_wave
from pdeanim.errors import ParameterError


def test_presets_follow_the_table():
    assert set(PRESETS) == {"eel", "trout", "tropical", "shark", "dolphin"}
    eel = SwimParams.preset("anguilliform")
    assert (eel.mode, eel.omega1, eel.alpha, eel.phi, eel.frequency) == ("eel", 0.3, 1.5, np.pi / 2, 1.0)
    assert SwimParams.preset("thunniform").mode == "shark"
    assert SwimParams.preset("dolphin").frequency == 1.3
    assert set(ALIASES.values()) <= set(PRESETS)


def test_overrides_and_round_trip():
    p = SwimParams.preset("trout", alpha=2.0, amplitude=0.2, wave="travelling")
    assert (p.alpha, p.amplitude, p.wave, p.omega1) == (2.0, 0.2, "travelling", 1.0)
    assert SwimParams.from_dict(p.to_dict()) == p


@pytest.mark.parametrize("bad", [{"frequency": 0}, {"amplitude": 2}, {"wave": "zigzag"}, {"radial": "x"},
                                 {"alpha": float("nan")}, {"speed": 1}, {"alpha": "fast"}])
def test_bad_parameters_raise(bad):
    with pytest.raises(ParameterError):
        SwimParams.preset("eel", **bad)


def test_unknown_mode_raises():
    with pytest.raises(ParameterError, match="unknown swim mode"):
        SwimParams.preset("cod")


@settings(max_examples=30, deadline=None)
@given(mode=st.sampled_from(sorted(PRESETS)), wave=st.sampled_from(["standing", "travelling"]),
       radial=st.sampled_from(["rotate", "translate"]), t=st.floats(-5, 5), freq=st.floats(0.2, 5))
def test_cycle_repeats_every_period(mode, wave, radial, t, freq):
    p = SwimParams.preset(mode, wave=wave, radial=radial, frequency=freq)
    s = np.linspace(0, 1, 50)
    rel = np.random.default_rng(0).normal(size=(50, 3)) * 0.05
    axis, lat = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    a = body_displacement(p, s, rel, np.ones(50), axis, lat, np.array([t]), 1.0)
    b = body_displacement(p, s, rel, np.ones(50), axis, lat, np.array([t + 1 / freq]), 1.0)
    assert np.abs(a - b).max() < 1e-12 * (1 + abs(t) * freq)


def test_standing_wave_is_zero_at_cycle_start_and_peaks_at_amplitude():
    p = SwimParams.preset("trout", amplitude=0.1)
    s = np.linspace(0, 1, 401)
    delta, _ = lateral_wave(p, s, np.array([0.0, 0.25 / p.frequency]), 2.0)
    assert np.array_equal(delta[0], np.zeros_like(s))
    assert np.abs(delta[1]).max() == pytest.approx(0.1 * 2.0, rel=1e-3)


def test_slope_matches_finite_difference():
    for wave in ("standing", "travelling"):
        p = SwimParams.preset("eel", wave=wave)
        s = np.linspace(0.01, 0.99, 30)
        t = np.array([0.13])
        _, slope = lateral_wave(p, s, t, 1.0)
        h = 1e-6
        fd = (lateral_wave(p, s + h, t, 1.0)[0] - lateral_wave(p, s - h, t, 1.0)[0]) / (2 * h)
        assert np.allclose(slope, fd, atol=1e-6)


def test_rotation_keeps_distance_to_the_spine():
    p = SwimParams.preset("eel", radial="rotate")
    s = np.linspace(0, 1, 40)
    rel = np.random.default_rng(1).normal(size=(40, 3)) * 0.03
    axis, lat = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    t = np.array([0.2])
    disp = body_displacement(p, s, rel, np.ones(40), axis, lat, t, 1.0)[0]
    delta, _ = lateral_wave(p, s, t, 1.0)
    moved_rel = rel + disp - delta[0][:, None] * lat
    assert np.allclose(np.linalg.norm(moved_rel, axis=1), np.linalg.norm(rel, axis=1), atol=1e-12)
    trans = body_displacement(
        SwimParams.preset("eel", radial="translate"), s, rel, np.ones(40), axis, lat, t, 1.0
    )
    assert np.allclose(trans[0], delta[0][:, None] * lat)


def test_vertical_wave_clip(trout_parts):
    from pdeanim import container
    from pdeanim.clip import load_clip
    from pdeanim.cyclic.clipcyclic import encode_coefficients
    from pdeanim.cyclic.spine import Spine

    _, ca = container.unpack(trout_parts.coefficients)
    params = SwimParams.preset("dolphin", direction="vertical")
    coef = encode_coefficients(trout_parts.topology, Spine(ca["spine"]), params, 24)
    clip = load_clip(trout_parts.topology, coef)
    shift = clip.evaluate(0.25) - clip.evaluate(0.0)
    up = np.abs(shift @ clip.frame.up).max()
    side = np.abs(shift @ clip.frame.lateral).max()
    assert up > 0.05 and side < 1e-6
