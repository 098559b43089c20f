"""segment_t is left out of a clip with a knot at every frame (docs/format.md §3.3): readers derive it from
the frame times, bit for bit what the writer had, and refuse its absence anywhere else."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim import container
from pdeanim.clip import load_clip
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model.clipformat import ClipFormatError, frame_segment_t
from pdeanim.model.coefwriter import segment_t_derivable
from tests.conformance.generate import _sphere_poses


@pytest.fixture(scope="module")
def dense():
    """A fit with a knot at every frame (13 frames, 12 segments) and one with 3 segments."""
    poses = _sphere_poses()
    return poses, fit_poses(poses, FitOptions(segments=12)), fit_poses(poses, FitOptions(segments=3))


def test_a_knot_at_every_frame_stores_no_segment_t_and_decodes_the_same(dense):
    poses, every, few = dense
    h, a = container.unpack(every.coefficients)
    assert h["n_segments"] + 1 == poses.n_frames and "segment_t" not in a
    assert "segment_t" in container.unpack(few.coefficients)[1]
    clip = load_clip(every.topology, every.coefficients)
    np.testing.assert_array_equal(clip.segment_t, frame_segment_t(poses.times))
    stored = container.pack(h, {**a, "segment_t": frame_segment_t(a["frame_times"])})
    t = np.linspace(0.0, 1.0, 29)
    np.testing.assert_array_equal(load_clip(every.topology, stored).evaluate(t), clip.evaluate(t))


def test_a_missing_segment_t_is_refused_without_a_knot_at_every_frame(dense):
    _, every, few = dense
    h, a = container.unpack(few.coefficients)
    without = {k: v for k, v in a.items() if k != "segment_t"}
    with pytest.raises(ClipFormatError, match="without segment_t need a knot at every frame"):
        load_clip(few.topology, container.pack(h, without))
    h, a = container.unpack(every.coefficients)
    flat = {**a, "frame_times": np.zeros_like(a["frame_times"])}
    with pytest.raises(ClipFormatError, match="without segment_t need a knot at every frame"):
        load_clip(every.topology, container.pack(h, flat))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=2, max_size=40, unique=True))
def test_derived_boundaries_rise_from_0_to_1(times):
    ft = np.sort(np.asarray(times, np.float64))
    seg = frame_segment_t(ft)
    assert seg[0] == 0.0 and seg[-1] == 1.0 and np.all(np.diff(seg) >= 0)
    assert segment_t_derivable(seg, ft) and not segment_t_derivable(seg[:-1], ft[:-1] * 0)
