"""Round trips and failure modes of the binary container, clip files and poses files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pdeanim import container
from pdeanim.clip import ClipParts, read_clip_file, write_clip_file
from pdeanim.errors import ClipFormatError, LimitError, PosesInputError
from pdeanim.poses import PoseLimits, load_poses_npz, make_poses, poses_to_bytes


@given(
    hnp.arrays(np.float32, hnp.array_shapes(max_dims=3, max_side=7), elements=st.floats(-1e6, 1e6, width=32)),
    hnp.arrays(np.int32, hnp.array_shapes(max_dims=2, max_side=5)),
)
def test_pack_unpack_round_trip(a, b):
    blob = container.pack({"part": "test", "n": 3}, {"a": a, "b": b})
    header, arrays = container.unpack(blob)
    assert header == {"part": "test", "n": 3}
    np.testing.assert_array_equal(arrays["a"], a)
    np.testing.assert_array_equal(arrays["b"], b)
    assert arrays["a"].dtype == np.float32 and arrays["b"].dtype == np.int32
    assert container.from_json(container.to_json(blob)) == blob


def test_arrays_are_aligned_and_little_endian():
    blob = container.pack({"part": "x"}, {"odd": np.arange(3, dtype=np.uint8), "f": np.ones(5, ">f4")})
    header, arrays = container.unpack(blob)
    assert arrays["f"].dtype.str == "<f4"
    assert (arrays["f"].ctypes.data - np.frombuffer(blob, np.uint8).ctypes.data) % 8 == 0


@pytest.mark.parametrize("blob", [b"", b"PDEANIM\0", b"garbage" * 10])
def test_bad_blobs_raise_clear_errors(blob):
    with pytest.raises(ClipFormatError):
        container.unpack(blob)


def test_truncated_blob_raises():
    blob = container.pack({"part": "x"}, {"a": np.arange(100, dtype=np.float32)})
    with pytest.raises(ClipFormatError, match="truncated|outside"):
        container.unpack(blob[:-16])


def test_clip_file_round_trip(tmp_path):
    parts = ClipParts(container.pack({"part": "topology"}, {}), container.pack({"part": "coefficients"}, {}),
                      {"rms": 1.0})
    write_clip_file(tmp_path / "c.clip", parts)
    back = read_clip_file(tmp_path / "c.clip")
    assert back.topology == parts.topology and back.coefficients == parts.coefficients
    assert back.report == {"rms": 1.0}


def test_poses_round_trip_and_validation(morph_sphere_path):
    poses = load_poses_npz(morph_sphere_path)
    assert poses.vertices.shape == (216, 1876, 3) and poses.faces.shape == (960, 3)
    again = load_poses_npz(poses_to_bytes(poses))
    np.testing.assert_array_equal(again.vertices, poses.vertices)
    bad = poses.vertices[:2].copy()
    bad[1, 5, 0] = np.nan
    with pytest.raises(PosesInputError, match="NaN"):
        make_poses(bad, poses.faces)
    with pytest.raises(PosesInputError, match="indices"):
        make_poses(poses.vertices[:2], poses.faces + 5000)
    with pytest.raises(LimitError):
        make_poses(poses.vertices, poses.faces, limits=PoseLimits(max_frames=10))
    with pytest.raises(PosesInputError):
        load_poses_npz(b"not a zip")


@given(
    hnp.arrays(st.sampled_from([np.float32, np.float64, np.int32, np.uint32, np.int16, np.uint8]),
               hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=6)),
    st.sampled_from(["zstd", "shuffle-zstd", container.SMALLEST]),
)
def test_encoded_arrays_round_trip(a, encoding):
    blob = container.pack({"part": "test"}, {"a": a, "raw": np.arange(3, dtype=np.int32)}, {"a": encoding})
    assert int.from_bytes(blob[8:12], "little") == 1
    header, arrays = container.unpack(blob)
    np.testing.assert_array_equal(arrays["a"], a)
    assert arrays["a"].dtype == a.dtype.newbyteorder("<") and arrays["a"].shape == a.shape
    assert container.pack({"part": "test"}, {"a": a}, {"a": encoding}) == container.pack(
        {"part": "test"}, {"a": a}, {"a": encoding})  # deterministic bytes


def _table_edit(blob: bytes, name: str, **changes) -> bytes:
    """The blob with one array entry of its JSON header changed (same header length)."""
    import json
    import struct

    _, version, hlen = struct.unpack_from("<8sII", blob)
    header = json.loads(blob[16:16 + hlen])
    header["arrays"][name].update(changes)
    meta = json.dumps(header, separators=(",", ":"), sort_keys=True).encode()
    meta += b" " * ((len(meta) + 7) // 8 * 8 - len(meta))
    return struct.pack("<8sII", b"PDEANIM\0", version, len(meta)) + meta + blob[16 + hlen:]


def test_bad_encoded_arrays_raise_clear_errors():
    a = np.arange(1000, dtype=np.uint32)
    blob = container.pack({"part": "x"}, {"a": a}, {"a": "shuffle-zstd"})
    with pytest.raises(ClipFormatError, match="unknown encoding"):
        container.unpack(_table_edit(blob, "a", encoding="lz4"))
    with pytest.raises(ClipFormatError, match="holds 4000 bytes, expected 8000"):
        container.unpack(_table_edit(blob, "a", shape=[2000]))  # the frame declares another size
    header_end = 16 + int.from_bytes(blob[12:16], "little")
    garbled = bytearray(blob)
    garbled[header_end + 12:header_end + 40] = b"\xff" * 28
    with pytest.raises(ClipFormatError, match="array 'a'"):
        container.unpack(bytes(garbled))
    with pytest.raises(ClipFormatError, match="truncated|outside"):
        container.unpack(blob[:-16])
    v2 = blob[:8] + (2).to_bytes(4, "little") + blob[12:]
    with pytest.raises(ClipFormatError, match="unsupported container version 2"):
        container.unpack(v2)


def test_the_container_version_is_1_with_and_without_encodings():
    for encodings in (None, {"a": "zstd"}):
        blob = container.pack({"part": "x"}, {"a": np.arange(4, dtype=np.int32)}, encodings)
        assert int.from_bytes(blob[8:12], "little") == 1


def test_trailing_bytes_after_the_zstd_frame_and_null_encodings_are_refused():
    import zstandard

    raw = np.arange(64, dtype="<u4").tobytes()
    frame = zstandard.ZstdCompressor(write_content_size=True).compress(raw)
    assert container.decode_array(frame, "zstd", np.dtype("<u4"), 64, "a").tobytes() == raw
    with pytest.raises(ClipFormatError, match="exactly one complete frame"):
        container.decode_array(frame + frame, "zstd", np.dtype("<u4"), 64, "a")
    blob = container.pack({"part": "x"}, {"a": np.arange(64, dtype=np.uint32)}, {"a": "zstd"})
    with pytest.raises(ClipFormatError, match="unknown encoding"):
        container.unpack(_table_edit(blob, "a", encoding=None))


def test_smallest_compresses_only_the_chosen_encoding_at_the_writers_level(monkeypatch):
    """SMALLEST compares the encodings at CHOICE_LEVEL and compresses just the winner at the final level."""
    a = np.cumsum(np.random.default_rng(3).integers(-3, 4, container.CHOICE_BYTES // 4)).astype(np.int32)
    levels = []
    real = container._encode
    monkeypatch.setattr(container, "_encode",
                        lambda arr, e, level=19: levels.append(level) or real(arr, e, level))
    blob = container.pack({"part": "x"}, {"a": a}, {"a": container.SMALLEST}, level=19)
    assert sorted(levels) == [container.CHOICE_LEVEL] * 2 + [19]
    np.testing.assert_array_equal(container.unpack(blob)[1]["a"], a)
    entry = json.loads(blob[16:16 + int.from_bytes(blob[12:16], "little")])["arrays"]["a"]
    trial = {e: len(real(a, e, container.CHOICE_LEVEL)) for e in container.ENCODINGS}
    assert entry["encoding"] == min(trial, key=trial.get)
    assert entry["nbytes"] == len(real(a, entry["encoding"], 19))
    levels.clear()
    small = container.pack({"part": "x"}, {"a": a[:1000]}, {"a": container.SMALLEST}, level=19)
    assert levels == [19, 19]  # small arrays: both encodings at the final level, the smaller kept
    final = {e: len(real(a[:1000], e, 19)) for e in container.ENCODINGS}
    assert len(small) - len(container.pack({"part": "x"}, {"a": a[:1000]},
                                           {"a": min(final, key=final.get)}, level=19)) == 0


def forged_part(declared: int) -> bytes:
    """A container whose one array is a genuine zstd frame of ``declared`` zero bytes (a tiny file that
    decodes to gigabytes), the array's shape and the frame's content size both saying so."""
    import io
    import struct

    import zstandard

    buf = io.BytesIO()
    with zstandard.ZstdCompressor(level=1).stream_writer(buf, size=declared, closefd=False) as writer:
        chunk = bytes(1 << 24)
        for _ in range(declared // len(chunk)):
            writer.write(chunk)
    frame = buf.getvalue()
    table = {"zeros": {"dtype": "<u1", "shape": [declared], "offset": 0, "nbytes": len(frame),
                       "encoding": "zstd"}}
    meta = json.dumps({"part": "coefficients", "arrays": table}).encode()
    meta += b" " * (-len(meta) % 8)
    return struct.pack("<8sII", container.MAGIC, container.VERSION, len(meta)) + meta + frame


def test_declared_sizes_past_the_expansion_limit_are_refused_before_decoding():
    blob = forged_part(1 << 30)
    assert len(blob) < 64 << 10  # 1 GiB of zeros in a few tens of KB
    with pytest.raises(ClipFormatError, match="declare 1073741824 bytes once decoded"):
        container.unpack(blob)
    assert container.decoded_limit(1 << 20) == container.MAX_EXPANSION * (1 << 20)
    assert container.decoded_limit(100 << 20) == container.MAX_DECODED_BYTES  # 8 GiB at most
    with pytest.raises(ClipFormatError, match="never over 1000"):
        container.unpack(container.pack({"part": "x"}, {"z": np.zeros(2000, np.uint8)}),
                         max_decoded_bytes=1000)
    big = np.zeros(2 << 20, np.uint8)  # 2 MiB of zeros packs into ~100 bytes: under the 64 MiB floor
    _, arrays = container.unpack(container.pack({"part": "x"}, {"z": big}, {"z": "zstd"}))
    assert arrays["z"].nbytes == big.nbytes


def test_forged_shapes_cannot_wrap_around():
    blob = container.pack({"part": "x"}, {"a": np.zeros(0, np.uint8)})
    forged = _table_edit(blob, "a", shape=[2**32, 2**32])  # 2^64 elements: 0 in int64 arithmetic
    with pytest.raises(ClipFormatError):
        container.unpack(forged)


def test_cli_frame_of_a_forged_clip_exits_2_without_a_traceback(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    real = read_clip_file(root / "clients" / "js" / "test" / "fixtures" / "fit-displacement-chord.clip")
    path = tmp_path / "forged.clip"
    write_clip_file(path, ClipParts(real.topology, forged_part(4 << 30), {}))
    assert path.stat().st_size < 200 << 10  # the file: 131 KB declaring 4 GiB
    run = subprocess.run([sys.executable, "-m", "pdeanim_service.cli", "frame", str(path), "--t", "0.5",
                          "--out",
                          str(tmp_path / "f.npz")], capture_output=True, text=True, cwd=root, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(root)})
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and "declare 4294967296 bytes" in run.stderr, run.stderr


def test_read_header_is_the_header_without_decoding_arrays():
    blob = container.pack({"part": "x", "n": 3}, {"a": np.arange(1000, dtype=np.float32)})
    assert container.read_header(blob) == container.unpack(blob)[0] == {"part": "x", "n": 3}
    header_only = blob[:16 + int.from_bytes(blob[12:16], "little")]  # the arrays cut off
    assert container.read_header(header_only)["n"] == 3
    with pytest.raises(ClipFormatError):
        container.unpack(header_only)
    for bad in (b"", b"NOTPDEAN" + blob[8:], blob[:12] + (10**6).to_bytes(4, "little") + blob[16:]):
        with pytest.raises(ClipFormatError):
            container.read_header(bad)
