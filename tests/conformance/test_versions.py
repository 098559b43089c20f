"""Readers refuse what they do not implement (docs/format.md §1-2): another container version, another major
format version (any "1.x" is read: minor versions only add what readers may ignore) and unknown kinds, while
unknown extra header keys and arrays are ignored."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from pdeanim import container
from pdeanim.clip import load_clip, read_clip_file
from pdeanim.errors import ClipFormatError

FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"


def _parts(name: str) -> tuple[bytes, bytes]:
    parts = read_clip_file(FIXTURES / f"{name}.clip")
    return parts.topology, parts.coefficients


def _edit(blob: bytes, **changes) -> bytes:
    header, arrays = container.unpack(blob)
    return container.pack({**header, **changes}, arrays)


def test_future_container_version_is_refused():
    topo, _ = _parts("fit-displacement-chord")
    for version in (0, 2):
        other = topo[:8] + struct.pack("<I", version) + topo[12:]
        with pytest.raises(ClipFormatError, match=f"unsupported container version {version}"):
            container.unpack(other)


@pytest.mark.parametrize("name", ["fit-displacement-chord", "synthetic-blend-displacement-paper-basis",
                                  "fit-displacement-chord-smooth-spline", "cyclic-eel-standing-rotate"])
def test_other_major_versions_are_refused_and_minor_ones_read(name):
    topo, coef = _parts(name)
    for bad in ("2.0", "0.9", 1, "1", "1.x", None):
        with pytest.raises(ClipFormatError, match="unsupported clip format version"):
            load_clip(topo, _edit(coef, format_version=bad))
        with pytest.raises(ClipFormatError, match="unsupported clip format version"):
            load_clip(_edit(topo, format_version=bad), _edit(coef, topology_id=None))
    plain = load_clip(topo, coef).evaluate(0.3)
    minor = load_clip(_edit(topo, format_version="1.7"), _edit(coef, format_version="1.12", topology_id=None))
    assert (minor.evaluate(0.3) == plain).all()


def test_unknown_extra_arrays_are_ignored():
    topo, coef = _parts("fit-displacement-chord-smooth-spline")
    header, arrays = container.unpack(coef)
    extended = container.pack(header, {**arrays, "some_future_array": arrays["D"] * 2})
    assert (load_clip(topo, extended).evaluate(0.6) == load_clip(topo, coef).evaluate(0.6)).all()


@pytest.mark.parametrize("name", ["fit-rigid-chord", "cyclic-dolphin-travelling-translate"])
def test_unknown_header_keys_are_ignored(name):
    topo, coef = _parts(name)
    plain = load_clip(topo, coef).evaluate(0.3)
    extended = load_clip(topo, _edit(coef, some_future_key={"x": 1})).evaluate(0.3)
    assert (plain == extended).all()


def test_unknown_kind_is_refused():
    topo, coef = _parts("fit-displacement-chord")
    with pytest.raises(ClipFormatError, match="unknown clip kind"):
        load_clip(topo, _edit(coef, kind="spline"))


def test_a_required_feature_the_reader_lacks_is_refused():
    import json

    refused = json.loads((FIXTURES / "manifest.json").read_text())["refused"]
    assert refused, "the fixtures hold a clip that requires an unknown feature"
    for case in refused:
        with pytest.raises(ClipFormatError, match=f"requires feature.*'{case['names']}'.*supports: bones"):
            read_clip_file(FIXTURES / case["clip"])
        header, arrays = container.unpack((FIXTURES / case["clip"]).read_bytes())
        with pytest.raises(ClipFormatError, match=case["names"]):  # the part itself, past the file header
            load_clip(arrays["topology"].tobytes(), arrays["coefficients"].tobytes())


def test_a_reader_without_bones_refuses_a_bone_clip_and_still_reads_1_0(monkeypatch):
    from pdeanim import clipparts

    topo, coef = _parts("bones-synthetic-k2-residual")
    assert container.unpack(coef)[0]["required"] == ["bones"]
    monkeypatch.setattr(clipparts, "SUPPORTED_FEATURES", ())
    with pytest.raises(ClipFormatError, match="requires feature.*'bones'"):
        load_clip(topo, coef)
    load_clip(*_parts("fit-displacement-chord"))  # no `required`: read as ever


@pytest.mark.parametrize("required", ["bones", [1], {"bones": 1}, [["bones"]]])
def test_required_must_be_a_list_of_names(required):
    topo, coef = _parts("bones-synthetic-k1-zero")
    with pytest.raises(ClipFormatError, match="'required' must be a list of feature names"):
        load_clip(topo, _edit(coef, required=required))


def test_bones_are_refused_on_a_cyclic_clip():
    topo, coef = _parts("cyclic-eel-standing-rotate")
    with pytest.raises(ClipFormatError, match="kind 'cyclic-spine' requires feature 'bones'"):
        load_clip(topo, _edit(coef, required=["bones"], format_version="1.1"))


def test_damaged_stream_indexes_are_refused():
    import json

    damaged = json.loads((FIXTURES / "manifest.json").read_text())["damaged"]
    assert damaged, "the fixtures hold streamable clips with a damaged index"
    for case in damaged:
        parts = read_clip_file(FIXTURES / case["clip"])  # the CLIP file itself is sound
        with pytest.raises(ClipFormatError, match=case["message"]):
            load_clip(parts.topology, parts.coefficients)


def test_a_reader_without_stream_refuses_a_stream_clip_by_name(monkeypatch):
    from pdeanim import clipparts

    topo, coef = _parts("stream-fit-displacement-chord-windows")
    assert container.read_header(coef)["required"] == ["stream"]
    monkeypatch.setattr(clipparts, "SUPPORTED_FEATURES", ("bones",))  # a 1.1 reader
    with pytest.raises(ClipFormatError, match="requires feature.*'stream'.*supports: bones"):
        load_clip(topo, coef)
    with pytest.raises(ClipFormatError, match="requires feature.*'stream'"):
        read_clip_file(FIXTURES / "stream-fit-displacement-chord-windows.clip")
