"""The one writer of the coefficients part (pdeanim.model.coefwriter) and the one zigzag encoder: a layer adds
header keys and arrays after format 1.0's, may not overwrite them, and a reader still decodes the part."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pdeanim.model import quantise
from pdeanim.model.clipformat import decode_coefficients
from pdeanim.model.coefwriter import CORE_ARRAYS, CoefficientFields, KnotCodes, write_coefficients


def _part(**layer):
    S, C = 3, 2
    rng = np.random.default_rng(0)
    codes = rng.integers(-50, 50, (S + 1, C, 3, 4))
    order = quantise.difference_order(np.moveaxis(codes, 0, -1))
    fields = CoefficientFields(np.linspace(0, 1, S + 1), np.arange(S + 1) / 24.0, np.zeros((C, 3), np.uint8),
                               np.zeros((C, 3), np.uint8), np.zeros((S, C, 3)), np.ones((C, 3)),
                               "displacement", False)
    knots = KnotCodes(np.full((C, 3), 2.0**-10, np.float32), quantise.knot_tracks(codes, order), order)
    return codes, write_coefficients(fields, knots, "t" * 64, {"errors": {"rms": 1.0}}, **layer)


def test_a_layer_adds_header_keys_and_arrays_after_the_core_ones_and_the_part_still_decodes():
    # a layer that no reader needs to know (required stays empty): readers ignore its key and array
    codes, (header, arrays) = _part(extra_header={"format_version": "1.1", "required": [], "layer_size": 4},
                                    extra_arrays={"layer_weights": np.ones((5, 4), np.float32)})
    assert header["format_version"] == "1.1" and header["required"] == [] and header["layer_size"] == 4
    assert header["errors"] == {"rms": 1.0} and header["knot_rank"] == 0
    assert list(arrays)[-1] == "layer_weights" and [a for a in arrays if a in CORE_ARRAYS] == [
        "frame_times", "space_kind", "time_model", "m", "D", "knot_step", "knots"]
    data = decode_coefficients(header, arrays, 2)
    np.testing.assert_array_equal(data.knots, codes * 2.0**-10)


@pytest.mark.parametrize("layer", [{"extra_header": {"n_curves": 9}}, {"extra_header": {"knot_rank": 1}},
                                   {"extra_arrays": {"knots": np.zeros(1)}}])
def test_a_layer_may_not_overwrite_the_core_part(layer):
    with pytest.raises(ValueError, match="may not overwrite"):
        _part(**layer)


@given(hnp.arrays(np.int32, st.integers(0, 40), elements=st.integers(-(2**31), 2**31 - 1)))
def test_the_zigzag_encoder_round_trips_in_place_or_not(d):
    z = quantise.zigzag(d)
    assert z.dtype == np.uint32 and np.array_equal(quantise.unzigzag(z), d)
    assert np.all(z[d >= 0] == 2 * d[d >= 0].astype(np.int64))
    inplace = quantise.zigzag(d.copy(), in_place=True)
    assert np.array_equal(inplace, z)


@given(hnp.arrays(np.int64, st.tuples(st.just(2), st.just(3), st.just(4), st.integers(1, 12)),
                  elements=st.integers(-(2**20), 2**20)),
       st.sampled_from([1, 2]))
def test_track_codes_in_place_equal_the_copying_ones_and_decode(tracks, order):
    copied = quantise.track_codes(tracks, order)
    inplace = quantise.track_codes(tracks.astype(np.int32), order, in_place=True)
    assert np.array_equal(copied, inplace)
    np.testing.assert_array_equal(quantise.decode_knot_tracks(copied, order), np.moveaxis(tracks, -1, 0))
