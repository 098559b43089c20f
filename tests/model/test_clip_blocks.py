"""A dynamic-PDE clip evaluated a block of curves at a time (pdeanim.model.clipblocks: what the service and
``pdeanim frame`` use for clips too large to decode whole) gives the decoded clip's positions bit for bit,
whatever the block size, with its large arrays spooled to scratch files (removed on close); and ``pdeanim
frame --t all`` writes the same arrays through either path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pdeanim.cli import frame as frame_cli
from pdeanim.cli import main
from pdeanim.clip import load_clip, load_clip_file, open_clip, read_clip_file
from pdeanim.model import clipblocks
from pdeanim.model.clipblocks import BlockedClip

FIXTURES = Path(__file__).resolve().parents[2] / "clients/js/test/fixtures"
NAMES = ["fit-displacement-chord-windows", "fit-rigid-chord-smooth-spline", "fit-absolute-paper",
         "fit-blend-displacement-chord-loop-basis", "synthetic-absolute-paper-loop-spline"]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("block_bytes", [1, 20_000, 1 << 30])
def test_blocks_give_the_decoded_clips_positions_bit_for_bit(name, block_bytes, monkeypatch, tmp_path):
    monkeypatch.setattr(clipblocks, "SPOOL_BYTES", 0)  # every per-curve array through a scratch file
    parts = read_clip_file(FIXTURES / f"{name}.clip")
    clip = load_clip(parts.topology, parts.coefficients)
    t = np.r_[clip.frame_t(), np.linspace(0.0, 1.0, 23), 1.37 if clip.looping else 0.999]
    with BlockedClip(parts.topology, parts.coefficients, block_bytes, tmp_path) as blocked:
        assert blocked.n_vertices == clip.n_vertices and np.array_equal(blocked.faces, clip.faces)
        assert blocked.info() == clip.info()
        assert blocked._large and not list(tmp_path.iterdir())  # in unlinked scratch files meanwhile
        assert (len(blocked.bounds) > 1) == (block_bytes < 1 << 30), blocked.bounds
        assert np.array_equal(blocked.evaluate(t).view(np.uint32), clip.evaluate(t).view(np.uint32))
        assert np.array_equal(blocked.evaluate(0.3).view(np.uint32), clip.evaluate(0.3).view(np.uint32))
    assert not blocked._files


def test_open_clip_decodes_whole_up_to_its_bound():
    parts = read_clip_file(FIXTURES / "fit-displacement-chord.clip")
    assert not isinstance(open_clip(parts.topology, parts.coefficients, 0), BlockedClip)
    assert not isinstance(open_clip(parts.topology, parts.coefficients, 1 << 30), BlockedClip)
    assert isinstance(open_clip(parts.topology, parts.coefficients, 1), BlockedClip)
    cyclic = read_clip_file(FIXTURES / "cyclic-eel-standing-rotate.clip")  # no blocks for this kind
    assert not isinstance(open_clip(cyclic.topology, cyclic.coefficients, 1), BlockedClip)


@pytest.mark.parametrize("name", ["fit-displacement-chord-windows", "cyclic-eel-standing-rotate"])
def test_frame_all_streams_the_same_arrays_through_either_path(name, tmp_path, monkeypatch):
    path = FIXTURES / f"{name}.clip"
    clip = load_clip_file(path)
    ft = clip.frame_times
    frame_t = (ft - ft[0]) / (ft[-1] - ft[0])
    want = clip.evaluate(frame_t)
    monkeypatch.setattr(frame_cli, "FRAME_BLOCK_BYTES", clip.n_vertices * 12 * 3)  # 3 frames per write
    for bound in (1 << 30, 1):  # decoded whole, then by blocks of curves
        monkeypatch.setattr(frame_cli, "DECODE_BYTES", bound)
        out = tmp_path / f"{bound}.npz"
        assert main(["frame", str(path), "--t", "all", "--out", str(out)]) == 0
        with np.load(out) as got:
            assert sorted(got.files) == ["faces", "t", "vertices"]
            assert np.array_equal(got["vertices"].view(np.uint32), want.view(np.uint32))
            assert np.array_equal(got["faces"], clip.faces) and np.array_equal(got["t"], frame_t)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1.npz", "1073741824.npz"]  # no scratch left
