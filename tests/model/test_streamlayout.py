"""The streamable layout (format 1.2, feature "stream", docs/format.md §3.10): a stream clip plays what its
source clip plays, every window decodes alone (bit for bit what the whole stream clip gives), a prefix that
ends after window 0 plays window 0, and a damaged index or window is refused."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from pdeanim import clipparts, container
from pdeanim.cli import main
from pdeanim.clip import ClipParts, clip_info, load_clip, read_clip_file, write_clip_file
from pdeanim.errors import ClipFormatError, ParameterError
from pdeanim.model.clipformat import decode_topology
from pdeanim.model.spline import clamped_tangents, natural_tangents
from pdeanim.model.streamlayout import (
    DEFAULT_TANGENT_BITS,
    STREAM_FEATURE,
    STREAM_VERSION,
    StreamClip,
    header_length,
    read_index,
    to_stream,
    window_bounds,
)

FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"
CASES = ["fit-displacement-chord-windows", "fit-absolute-chord-smooth-spline",
         "fit-rigid-chord-smooth-spline",
         "synthetic-blend-absolute-chord-basis-spline", "fit-blend-displacement-chord-loop-basis",
         "synthetic-absolute-paper-loop-spline", "bones-synthetic-k4-residual", "bones-fit-k4-residual",
         "bones-synthetic-k3-zero-loop", "fit-displacement-chord-smooth-pde", "fit-rigid-single-frame"]
FLOAT32_TOLERANCE = 2.0**-21
"""Float32 re-rounding, relative to the largest coordinate: spline fields solved from other end conditions
(measured at most 1.7e-7, 2^-22.5)."""
TANGENT_TOLERANCE = 1.5
"""A spline value near an inner window bound moves by at most (0.19 x the space basis sum, at most 6) x the
tangent's rounding, 2^-(tangent_bits + 1) knot steps (docs/format.md §3.10): tolerance 1.5 x 2^-(bits + 1) x
the largest knot step; measured 0.74 x (the -windows fixtures, 4 bits)."""


def _parts(name: str) -> ClipParts:
    return read_clip_file(FIXTURES / f"{name}.clip")


def _times(clip, n: int = 61) -> np.ndarray:
    return np.linspace(-0.25, 1.3, n) if clip.looping else np.linspace(0.0, 1.0, n)


@pytest.fixture(scope="module", params=CASES)
def case(request):
    parts = _parts(request.param)
    stream = to_stream(parts, window_seconds=0.12)
    return request.param, parts, stream


def test_stream_clip_plays_its_source(case):
    name, parts, stream = case
    source = load_clip(parts.topology, parts.coefficients)
    clip = load_clip(stream.topology, stream.coefficients)
    assert isinstance(clip, StreamClip)
    header = container.read_header(stream.coefficients)
    assert header["format_version"] == STREAM_VERSION and STREAM_FEATURE in header["required"]
    assert ("bones" in header["required"]) == name.startswith("bones-")
    t = _times(source)
    want, got = source.evaluate(t), clip.evaluate(t)
    step = float(np.max(container.unpack(parts.coefficients)[1]["knot_step"]))
    bits = DEFAULT_TANGENT_BITS
    tol = FLOAT32_TOLERANCE * float(np.abs(want).max()) + TANGENT_TOLERANCE * 2.0**-(bits + 1) * step
    assert np.abs(got - want).max() <= tol, name
    spline = source.coef.spline_items().any() or (
        source.bones is not None and source.bones.tracks.tangents is not None)
    if not spline:  # time pairs only: the same float32 knots, fields and frames
        np.testing.assert_array_equal(got, want)
    assert clip.evaluate(0.37).shape == (source.n_vertices, 3)
    info, whole = clip.info(), source.info()
    assert info.pop("stream")["n_windows"] == len(clip.windows)
    assert info == whole
    assert clip_info(stream.topology, stream.coefficients) == clip.info()


def test_every_window_decodes_alone_with_its_start_state(case):
    name, parts, stream = case
    clip = load_clip(stream.topology, stream.coefficients)
    blob = stream.coefficients
    header, _, windows = read_index(blob)
    topo = decode_topology(*container.unpack(stream.topology))
    head = StreamClip.from_prefix(topo, blob[:windows[0].start]).head  # the head alone, no window
    for w in windows:
        own = clip.self_contained(w.index)  # the window with its start state (the per-window route's bytes)
        alone = head.window(w.index, own)  # decoded from the head and these bytes, nothing else
        if w.index:
            assert len(own) > w.nbytes
            with pytest.raises(ClipFormatError, match=f"window {w.index} continues window {w.index - 1}"):
                head.window(w.index, blob[w.start:w.end])
        last = w.index == len(windows) - 1 and not clip.looping  # a looping clip's t = 1 is t = 0
        t = np.linspace(w.t0, w.t1, 7)[:None if last else -1]
        np.testing.assert_array_equal(alone.evaluate(t), clip.evaluate(t))


def test_a_prefix_ending_after_window_0_plays_window_0(case):
    name, parts, stream = case
    blob = stream.coefficients
    _, _, windows = read_index(blob[:windows_header_end(blob)])
    topo = decode_topology(*container.unpack(stream.topology))
    whole = StreamClip(topo, blob)
    first = StreamClip.from_prefix(topo, blob[:windows[0].end])
    assert first.available() == 1 or len(windows) == 1
    t = np.linspace(0.0, windows[0].t1, 5)[:-1]
    np.testing.assert_array_equal(first.evaluate(t), whole.evaluate(t))
    if len(windows) > 1:
        with pytest.raises(ClipFormatError, match="window 1 .* not in the"):
            first.evaluate(windows[1].t0)
        two = StreamClip.from_prefix(topo, blob[:windows[1].end])  # window 1 continues window 0's state
        t = np.linspace(windows[1].t0, windows[1].t1, 5)[:-1]
        np.testing.assert_array_equal(two.evaluate(t), whole.evaluate(t))
        with pytest.raises(ClipFormatError, match="not complete|not in the bytes"):
            StreamClip.from_prefix(topo, blob[:windows_header_end(blob) + 8])  # the head not all there


def windows_header_end(blob: bytes) -> int:
    """Bytes a streaming reader needs for the index: the prefix and header, nothing else."""
    return header_length(blob[:16])


def _with_index(blob: bytes, edit) -> bytes:  # noqa: ANN001 - edit(stream index) changes it in place
    header = container.read_header(blob)
    stream = json.loads(json.dumps(header["stream"]))
    edit(stream)
    return container.with_header(blob, {"stream": stream})


@pytest.mark.parametrize("edit, why", [
    (lambda s: s["windows"][0].update(offset=s["windows"][0]["offset"] + 8), "offset/nbytes"),
    (lambda s: s["windows"][0].update(nbytes=s["windows"][0]["nbytes"] - 1), "offset/nbytes"),
    (lambda s: s["windows"][1]["t"].__setitem__(0, 0.5 * s["windows"][1]["t"][0]), "does not start where"),
    (lambda s: s["windows"][1]["knots"].__setitem__(0, s["windows"][1]["knots"][0] + 1),
     "does not start where"),
    (lambda s: s["windows"][-1]["t"].__setitem__(1, 0.99), "last window must end"),
    (lambda s: s.update(n_windows=s["n_windows"] + 1), "n_windows"),
    (lambda s: s["windows"].reverse(), "window 0 must start|does not start where"),
    (lambda s: s["windows"][0].update(array="topology"), "does not hold"),
    (lambda s: s["windows"][0].pop("t"), "lacks a valid"),
    (lambda s: s.pop("windows"), "no 'stream' object"),
])
def test_a_damaged_index_is_refused(edit, why):
    parts = to_stream(_parts("fit-displacement-chord-windows"), window_seconds=0.12)
    bad = _with_index(parts.coefficients, edit)
    with pytest.raises(ClipFormatError, match=f"damaged stream index: .*({why})"):
        load_clip(parts.topology, bad)


def test_a_window_disagreeing_with_the_index_is_refused():
    parts = to_stream(_parts("fit-displacement-chord-smooth-pde"), window_seconds=0.12)
    blob = parts.coefficients
    _, _, windows = read_index(blob)
    w = windows[1]
    inner = blob[w.start:w.end]
    forged = container.with_header(inner, {"window": 0})
    assert len(forged) == len(inner)  # same size: only the header differs
    bad = blob[:w.start] + forged + blob[w.end:]
    with pytest.raises(ClipFormatError, match="window 1's own header disagrees"):
        load_clip(parts.topology, bad).evaluate(w.t0)  # refused at load (its probe times) or here
    topo = decode_topology(*container.unpack(parts.topology))
    early = StreamClip.from_prefix(topo, bad[:windows[0].end])  # window 0 is intact and plays
    np.testing.assert_array_equal(early.evaluate(0.0), load_clip(parts.topology, blob).evaluate(0.0))
    blank = struct.pack("<8sII", b"PDEANIM\0", 1, 8) + b" " * (w.nbytes - 16)  # no valid header
    truncated = blob[:w.start] + blank + blob[w.end:]
    with pytest.raises(ClipFormatError):
        load_clip(parts.topology, truncated).evaluate(w.t0)


def test_readers_without_the_feature_refuse_it_by_name(monkeypatch, tmp_path):
    parts = to_stream(_parts("bones-fit-k4-residual"))
    path = tmp_path / "s.clip"
    write_clip_file(path, parts)
    outer = container.read_header(path.read_bytes())
    assert outer["format_version"] == "1.2" and outer["required"] == ["bones", "stream"]
    again = read_clip_file(path)
    np.testing.assert_array_equal(load_clip(again.topology, again.coefficients).evaluate(0.4),
                                  load_clip(parts.topology, parts.coefficients).evaluate(0.4))
    monkeypatch.setattr(clipparts, "SUPPORTED_FEATURES", ("bones",))  # a 1.1 reader
    with pytest.raises(ClipFormatError, match="requires feature.*'stream'.*supports: bones"):
        read_clip_file(path)
    with pytest.raises(ClipFormatError, match="'stream'"):
        load_clip(parts.topology, parts.coefficients)


def test_window_bounds():
    seg = np.linspace(0.0, 1.0, 11)
    ft = np.linspace(0.0, 10.0, 11)  # one second a segment
    assert window_bounds(seg, ft, None, 3.0) == [0, 3, 6, 9, 10]
    assert window_bounds(seg, ft, None, 100.0) == [0, 10]
    assert window_bounds(seg, ft, np.array([0, 2, 7, 11]), 100.0) == [0, 2, 7, 10]
    assert window_bounds(seg, ft, None, 100.0, max_window_segments=4) == [0, 4, 8, 10]
    flat = np.array([0.0, 0.5, 0.5, 0.5, 1.0])  # zero-length segments: a window never has zero duration
    bounds = window_bounds(flat, np.array([0.0, 1.0]), None, 1e-9)
    assert all(flat[a] < flat[b] for a, b in zip(bounds[:-1], bounds[1:], strict=True))


def test_clamped_tangents_continue_the_natural_spline():
    rng = np.random.default_rng(3)
    t = np.concatenate([[0.0], np.sort(rng.uniform(0, 1, 30)), [1.0]])
    P = rng.normal(size=(len(t), 5))
    T = natural_tangents(P, t)
    for a, b in ((0, len(t) - 1), (3, 4), (5, 17), (0, 2)):
        inner = clamped_tangents(P[a:b + 1], t[a:b + 1], T[a], T[b])
        np.testing.assert_allclose(inner, T[a:b + 1], rtol=1e-11, atol=1e-11 * np.abs(T).max())


def test_conversion_refusals_and_idempotence():
    stream = to_stream(_parts("fit-displacement-chord"))
    assert to_stream(stream).coefficients == stream.coefficients
    with pytest.raises(ParameterError, match="only dynamic-pde"):
        to_stream(_parts("cyclic-eel-standing-rotate"))
    with pytest.raises(ParameterError, match="window_seconds"):
        to_stream(_parts("fit-displacement-chord"), window_seconds=0.0)


def test_cli_stream_and_fit_layout(tmp_path, capsys):
    out = tmp_path / "s.clip"
    assert main(["stream", str(FIXTURES / "fit-displacement-chord-windows.clip"), "--out", str(out),
                 "--window-seconds", "0.1"]) == 0
    assert "streamable layout" in capsys.readouterr().out
    parts = read_clip_file(out)
    assert read_index(parts.coefficients)[2][0].first_knot == 0
    assert main(["stream", str(FIXTURES / "fit-displacement-chord.clip"), "--out", str(out),
                 "--window-seconds", "-1"]) == 2
    assert main(["stream", str(FIXTURES / "cyclic-eel-standing-rotate.clip"), "--out", str(out)]) == 2
