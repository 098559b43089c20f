"""The one "does this error meet the target" rule (pdeanim.model.targets.Targets): at or below the target is
met, a zero target is met by a zero error only, a target not given is always met, and ``excess`` agrees."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pdeanim.model.targets import Targets

errors = st.floats(0.0, 1e6, allow_nan=False)
goals = st.one_of(st.none(), st.just(0.0), st.floats(1e-12, 1e6))


@given(errors, errors, goals, goals)
def test_meets_is_at_most_every_target_given(rms, largest, t_rms, t_max):
    t = Targets(t_rms, t_max)
    expected = (t_rms is None or rms <= t_rms) and (t_max is None or largest <= t_max)
    assert t.meets(rms, largest) is expected
    missed = (t_rms is not None and rms > t_rms, t_max is not None and largest > t_max)
    assert t.misses(rms, largest) == missed


@given(errors, errors, goals, goals)
def test_excess_is_at_most_one_when_met_and_at_least_one_when_missed(rms, largest, t_rms, t_max):
    t = Targets(t_rms, t_max)
    e = t.excess(rms, largest)
    assert e >= 0.0 and not math.isnan(e)
    if t.meets(rms, largest):
        assert e <= 1.0
    else:
        assert e >= 1.0


@given(errors, goals)
def test_a_zero_target_is_met_by_a_zero_error_only(error, other):
    t = Targets(0.0, other)
    assert t.excess(0.0, 0.0) == 0.0 and t.meets(0.0, 0.0) is (other is None or other >= 0.0)
    if error > 0:
        assert not t.meets(error, 0.0) and t.excess(error, 0.0) == math.inf


@given(st.lists(st.floats(0.0, 1e3), min_size=1, max_size=40), goals, goals)
def test_met_by_distances_and_elementwise_excess_agree_with_the_scalar_rule(d, t_rms, t_max):
    t = Targets(t_rms, t_max)
    a = np.asarray(d).reshape(1, -1)
    assert t.met_by(a) is t.meets(float(np.sqrt(np.mean(a * a))), float(a.max()))
    per = t.excess(np.asarray(d), np.asarray(d))
    assert per.shape == (len(d),)
    assert [float(x) for x in per] == [t.excess(x, x) for x in d]


def test_no_targets_are_always_met():
    assert Targets().meets(1e30, 1e30) and Targets().excess(5.0, 7.0) == 0.0
