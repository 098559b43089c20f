"""Readers refuse what they do not implement (docs/format.md, section 5): future container, dynamic-PDE and
cyclic-spine versions and unknown kinds, while unknown extra header keys are ignored."""

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
    future = topo[:8] + struct.pack("<I", 3) + topo[12:]
    with pytest.raises(ClipFormatError, match="unsupported container version 3"):
        container.unpack(future)


@pytest.mark.parametrize(("name", "future_coefficients", "future_topology"),
                         [("fit-displacement-chord", 6, 3), ("synthetic-blend-displacement-paper-v3", 6, 3),
                          ("cyclic-eel-standing-rotate", 2, 2)])
def test_future_format_versions_are_refused(name, future_coefficients, future_topology):
    """dynamic-pde coefficients read versions 1-5 but topology parts only 1-2 (versions 3 to 5 change the
    coefficients part only); cyclic-spine parts read version 1."""
    topo, coef = _parts(name)
    with pytest.raises(ClipFormatError, match=f"coefficients version {future_coefficients}"):
        load_clip(topo, _edit(coef, format_version=future_coefficients))
    new_topo = _edit(topo, format_version=future_topology)
    with pytest.raises(ClipFormatError, match=f"topology version {future_topology}"):
        load_clip(new_topo, _edit(coef, topology_id=None))


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
