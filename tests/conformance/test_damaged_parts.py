"""Damaged or hand-made parts: whatever a header field or array value says, loading a clip either works and
evaluates to finite positions or raises ClipFormatError (the CLI's exit 2, the API's 4xx) - never another
exception, a huge allocation or NaN frames. Seeded mutations of the conformance fixtures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pdeanim import container
from pdeanim.clip import load_clip, read_clip_file, topology_id
from pdeanim.errors import ClipFormatError

FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"
ODD_VALUES = [0, -1, 1e30, 2**40, "x", None, [1, 2], 3]


def _mutated(rng: np.random.Generator, header: dict, arrays: dict) -> tuple[dict, dict]:
    """One random change: a header field set to an odd value, a few array values, or a shortened array."""
    header, arrays = dict(header), {k: np.array(v) for k, v in arrays.items()}
    names = sorted(arrays)
    pick = int(rng.integers(0, len(names) + 1))
    if pick == len(names):
        key = sorted(k for k in header if k not in ("part", "kind", "topology_id"))[
            int(rng.integers(0, len(header) - 3))]
        header[key] = ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))]
        return header, arrays
    a = arrays[names[pick]]
    if a.size and rng.random() < 0.7:
        flat = a.reshape(-1)
        at = rng.integers(0, flat.size, size=int(rng.integers(1, 4)))
        if flat.dtype.kind == "f":
            flat[at] = [np.nan, np.inf, -1.0, 1e30, 0.0, 5.0][int(rng.integers(0, 6))]
        else:
            info = np.iinfo(flat.dtype)
            flat[at] = rng.integers(info.min, info.max, size=len(at), dtype=np.int64, endpoint=True)
    else:
        arrays[names[pick]] = a.reshape(-1)[: max(a.size - 1, 0)]
    return header, arrays


@pytest.mark.parametrize("name", ["fit-displacement-chord-smooth-spline", "fit-rigid-chord",
                                  "fit-rigid-paper-loop", "synthetic-blend-rigid-chord-loop-basis",
                                  "cyclic-dolphin-travelling-translate"])
def test_damaged_parts_load_or_raise_clip_format_error(name):
    parts = read_clip_file(FIXTURES / f"{name}.clip")
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    rng = np.random.default_rng(7)
    refused = 0
    for _ in range(150):
        if rng.random() < 0.5:
            topo = container.pack(*_mutated(rng, th, ta))
            coef = container.pack({**ch, "topology_id": topology_id(topo)}, dict(ca))
        else:
            topo = parts.topology
            h, a = _mutated(rng, ch, ca)
            coef = container.pack({**h, "topology_id": topology_id(topo)}, a)
        try:
            clip = load_clip(topo, coef)
        except ClipFormatError:
            refused += 1
            continue
        with np.errstate(all="ignore"):
            assert np.all(np.isfinite(clip.evaluate(np.array([0.0, 0.37, 1.0]))))
    assert refused > 10  # the mutations do reach the checks


@pytest.mark.parametrize("knot", [1.6e38, 2.0**97])
def test_a_finite_knot_whose_frames_would_overflow_is_refused_at_load(knot):
    """One finite knot of 1.6e38 (the largest float32s are finite, yet its frames between the probed times are
    not): refused at load naming the limit, not at some later frame."""
    parts = read_clip_file(FIXTURES / "fit-absolute-chord-pde.clip")
    ch, ca = container.unpack(parts.coefficients)
    assert ch["knot_rank"] == 0 and "knot_windows" not in ca
    from pdeanim.model import quantise

    codes = quantise.decode_knot_tracks(ca["knots"], ch["knot_differences"])  # (S+1, C, 3, 4)
    s, c, w, k = (int(i[0]) for i in np.nonzero(codes))
    steps = np.array(ca["knot_step"])
    steps[c, w] = np.float32(abs(knot / codes[s, c, w, k]))  # that knot is +-knot
    coef = container.pack(ch, {**ca, "knot_step": steps})
    with pytest.raises(ClipFormatError, match="above 2\\^96"):
        load_clip(parts.topology, coef)
