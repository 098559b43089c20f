"""A clip's metadata read from its parts' headers (what ``GET /v1/clips/{id}`` answers without decoding a
long clip's evaluation tables) equals the decoded clip's ``info()``, for every fixture clip of every kind."""

from __future__ import annotations

from pathlib import Path

import pytest

from pdeanim import container
from pdeanim.clip import clip_info, load_clip, read_clip_file
from pdeanim.errors import ClipFormatError

ALL = sorted((Path(__file__).resolve().parents[2] / "clients/js/test/fixtures").glob("*.clip"))
FIXTURES = [p for p in ALL if not p.stem.startswith(("refused-", "damaged-"))]  # refused ones aside


@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.stem)
def test_header_info_equals_the_decoded_clips_info(path: Path):
    parts = read_clip_file(path)
    decoded = load_clip(parts.topology, parts.coefficients).info()
    assert clip_info(parts.topology, parts.coefficients) == decoded


@pytest.mark.parametrize("path", [p for p in ALL if p not in FIXTURES], ids=lambda p: p.stem)
def test_header_info_refuses_a_clip_needing_a_feature_it_lacks(path: Path):
    """The refused clips name a future feature; the damaged ones a damaged stream index."""
    why = "damaged stream index" if path.stem.startswith("damaged-") else "x-future-(feature|stream)"
    with pytest.raises(ClipFormatError, match=why):
        parts = read_clip_file(path)
        clip_info(parts.topology, parts.coefficients)


def test_header_info_decodes_only_the_frame_times_and_checks_the_parts():
    parts = read_clip_file(next(p for p in FIXTURES if p.stem == "fit-displacement-chord-windows"))
    header, arrays = container.unpack(parts.coefficients, names=("frame_times",))
    assert set(arrays) == {"frame_times"} and header["kind"] == "dynamic-pde"
    with pytest.raises(ClipFormatError, match="topology_id mismatch"):
        other = read_clip_file(next(p for p in FIXTURES if p.stem == "fit-rigid-chord"))
        clip_info(other.topology, parts.coefficients)
    with pytest.raises(ClipFormatError, match="expected a topology part"):
        clip_info(parts.coefficients, parts.coefficients)


@pytest.mark.parametrize("path", FIXTURES[::4], ids=lambda p: p.stem)
@pytest.mark.parametrize("spool", [0, container.SPOOL_BYTES])  # arrays through scratch files, or in memory
def test_json_form_in_pieces_is_the_json_form(path: Path, spool: int, monkeypatch):
    import json

    monkeypatch.setattr(container, "SPOOL_BYTES", spool)
    parts = read_clip_file(path)
    for blob in (parts.topology, parts.coefficients):
        want = json.dumps(container.to_json(blob)).encode()
        assert all(b"".join(container.iter_json(blob, chunk)) == want for chunk in (1, 7, 1 << 16))
