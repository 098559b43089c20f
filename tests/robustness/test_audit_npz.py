"""Audit defects 1, 3 and 8 (complex poses): hostile .npz poses are refused with a clear InputError, from
their npy headers alone (bounded memory), never with a MemoryError, NotImplementedError or RuntimeError."""

from __future__ import annotations

import io
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

from pdeanim.errors import InputError, LimitError, PosesInputError
from pdeanim.poses import PoseLimits, load_poses_npz


def npz(**arrays: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def zeros_bomb(shape: tuple[int, ...], dtype: str = "<f4") -> bytes:
    """A compressed .npz whose 'vertices' member inflates to prod(shape) zeros, written in chunks."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": dtype, "fortran_order": False, "shape": shape})
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf, \
            zf.open("vertices.npy", "w", force_zip64=True) as m:
        m.write(header.getvalue())
        chunk = bytes(1 << 22)
        left = int(np.prod(shape)) * np.dtype(dtype).itemsize
        while left:
            m.write(chunk[:min(left, len(chunk))])
            left -= min(left, len(chunk))
    return out.getvalue()


def declared_only(shape: tuple[int, ...]) -> bytes:
    """A stored .npz whose npy header declares ``shape`` but holds only a few bytes of data."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": shape})
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as zf:
        zf.writestr("vertices.npy", header.getvalue() + bytes(64))
    return out.getvalue()


def patch_local_and_central(blob: bytes, offset_in_header: int, fmt: str, value: int) -> bytes:
    """Overwrite a field of every local (PK\\3\\4) and central (PK\\1\\2) zip header."""
    data = bytearray(blob)
    # central headers have 'version made by' first, so their fields sit 2 bytes later
    for sig, extra in ((b"PK\x03\x04", 0), (b"PK\x01\x02", 2)):
        pos = data.find(sig)
        while pos >= 0:
            struct.pack_into(fmt, data, pos + offset_in_header + extra, value)
            pos = data.find(sig, pos + 4)
    return bytes(data)


GOOD = npz(vertices=np.zeros((3, 4, 3), np.float32), faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32))


def test_bomb_refused_before_inflating():
    """Defect 1: 3000 frames of 2930 vertices (105 MB of zeros in ~100 kB) against a 2000-frame limit: refused
    from the header, with the reader's peak allocation far below the inflated size."""
    bomb = zeros_bomb((3000, 2930, 3))
    assert len(bomb) < 1_000_000
    tracemalloc.start()
    try:
        with pytest.raises(LimitError, match="frame count"):
            load_poses_npz(bomb, PoseLimits(max_frames=2000, max_vertices=500_000))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # inflating would allocate 105 MB; reading the headers needs the zip directory and a few kB of buffers
    assert peak < 10_000_000, peak


def test_inflated_bytes_limit():
    """Arrays within the frame/vertex limits but over the inflated-bytes limit are refused from the header."""
    with pytest.raises(LimitError, match="inflated size"):
        load_poses_npz(zeros_bomb((100, 1000, 3)), PoseLimits(max_bytes=1_000_000))


@pytest.mark.parametrize("name", ["method99", "encrypted", "huge_shape", "truncated", "garbage", "object"])
def test_malformed_npz_is_input_error(name):
    """Defect 3: each malformed archive raises PosesInputError (HTTP 422), never a 500-type exception."""
    blob = {
        "method99": lambda: patch_local_and_central(GOOD, 8, "<H", 99),       # compression method field
        "encrypted": lambda: patch_local_and_central(GOOD, 6, "<H", 0x1),     # general purpose flags
        "huge_shape": lambda: declared_only((100_000_000, 2930, 3)),
        "truncated": lambda: declared_only((3, 4, 3)),
        "garbage": lambda: b"PK\x03\x04" + bytes(100),
        "object": lambda: npz(vertices=np.array([None, 1], dtype=object)),
    }[name]()
    with pytest.raises(InputError) as info:
        load_poses_npz(blob, PoseLimits())
    assert info.value.code in ("invalid_poses", "limit_exceeded") and str(info.value)


@pytest.mark.parametrize("member", ["vertices", "times"])
def test_complex_arrays_refused(member):
    """Defect 8: complex-valued poses (or times) are refused, not silently cast to their real part."""
    arrays = {"vertices": np.zeros((2, 3, 3), np.float32), "times": np.array([0.0, 0.5])}
    arrays[member] = arrays[member].astype(np.complex64) + 1j
    with pytest.raises(PosesInputError, match="real numbers"):
        load_poses_npz(npz(**arrays))


def test_good_npz_still_reads():
    poses = load_poses_npz(GOOD)
    assert poses.vertices.shape == (3, 4, 3) and poses.faces.shape == (2, 3)
