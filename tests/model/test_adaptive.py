"""The error-driven segment search: how fast the number of segments grows, and where merging is tried."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pdeanim.fit import FitOptions, FitTolerances, fit_poses
from pdeanim.model import adaptive
from pdeanim.model.adaptive import GROWTH_MAX, GROWTH_MIN, Targets, _split_count
from pdeanim.poses import make_poses


@given(st.integers(1, 5000), st.floats(1e-3, 1e4))
def test_split_count_grows_with_the_square_root_of_the_error_ratio(n, ratio):
    k = _split_count(n, ratio, ratio, Targets(rms=1.0))  # RMS and largest distance: ratio x the target
    growth = float(np.clip(np.sqrt(ratio), GROWTH_MIN, GROWTH_MAX))
    assert 0 <= k <= n and abs(k - n * (growth - 1.0)) < 1.0
    if ratio >= GROWTH_MAX**2:
        assert k == n  # far from the target: every segment splits
    if ratio <= GROWTH_MIN**2:
        assert k == n // 3  # close to it: a third of them, as before the growth was error-driven
    assert _split_count(n, ratio, ratio, Targets(rms=1.0, max=0.5 * ratio)) >= k  # a missed max target counts


def _travelling_wave(frames: int = 121) -> tuple:
    """A strip of quads carrying a wave that travels along it: the error falls with the segment count."""
    x, y = np.meshgrid(np.linspace(0.0, 4.0, 41), np.linspace(0.0, 0.4, 3))
    rest = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    t = np.linspace(0.0, 1.0, frames)[:, None]
    z = 0.2 * np.sin(2.0 * np.pi * (rest[None, :, 0] / 4.0 - 3.0 * t))
    vertices = np.repeat(rest[None], frames, axis=0)
    vertices[:, :, 2] = z
    i = np.arange(40)[:, None] + 41 * np.arange(2)[None, :]
    quads = np.stack([i, i + 1, i + 42, i + 41], axis=-1).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return make_poses(vertices.astype(np.float32), faces, np.linspace(0.0, 4.0, frames))


def test_search_doubles_far_from_the_target_and_skips_merging_many_segments(monkeypatch):
    merges = []
    real = adaptive._merge
    monkeypatch.setattr(adaptive, "_merge", lambda *a, **k: merges.append(1) or real(*a, **k))
    r = fit_poses(_travelling_wave(), FitOptions(target_rel_rms=1e-3, time_model="pde"),
                  tolerances=FitTolerances(dense_fit=False)).report  # the search alone
    counts = [h["segments"] for h in r["adaptive_history"] if not h.get("merged")]
    assert r["target_met"] is True and counts[-1] > adaptive.MERGE_MAX_SEGMENTS
    steps = np.diff(counts)
    assert np.all(steps >= np.floor(np.array(counts[:-1]) / 3)) and np.all(steps <= np.array(counts[:-1]))
    assert counts[:4] == [1, 2, 4, 8]  # far from the target every segment splits
    assert not merges
