"""Read named arrays from an untrusted .npz with bounded memory: every member's zip entry and npy header
(shape, dtype) is checked against the caller's limits before any array data is inflated, so a small
compressed file cannot make the reader allocate gigabytes, and malformed archives become one clear
InputError."""

from __future__ import annotations

import io
import math
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

from .errors import InputError

SUPPORTED_METHODS = {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
_FAILURES = (ValueError, EOFError, OSError, zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error,
             NotImplementedError, RuntimeError, KeyError, UnicodeDecodeError)


@dataclass(frozen=True)
class ArrayHeader:
    """What an npy header declares about one member."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype

    @property
    def count(self) -> int:
        """Number of values (exact Python int: no overflow on absurd shapes)."""
        return math.prod(self.shape)

    @property
    def nbytes(self) -> int:
        """Bytes the array takes once inflated."""
        return self.count * self.dtype.itemsize


Checker = Callable[[dict[str, ArrayHeader]], None]
"""Called with the headers of the wanted members that exist; raises to refuse before anything is inflated."""


def _header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, error: type[InputError]) -> ArrayHeader:
    if info.flag_bits & 0x1:
        raise error(f"member {name!r} of the .npz is encrypted")
    if info.compress_type not in SUPPORTED_METHODS:
        raise error(f"member {name!r} of the .npz uses unsupported compression method {info.compress_type}")
    with zf.open(info) as fh:
        version = npy_format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = npy_format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = npy_format.read_array_header_2_0(fh)
        else:
            raise error(f"member {name!r} has npy format version {version}: only 1.0 and 2.0 are read")
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None:
        raise error(f"member {name!r} has dtype {dtype}: only plain numeric arrays are accepted")
    return ArrayHeader(name, tuple(int(s) for s in shape), dtype)


def read_npz(source: str | Path | bytes, names: tuple[str, ...], check: Checker,
             error: type[InputError] = InputError, skip: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """The members ``names`` (without ``.npy``) of an .npz that exist, after ``check`` accepted their headers
    (those in ``skip`` are checked but not read).

    Malformed archives (bad zip, encrypted or unknown-method members, corrupt streams, bad npy headers,
    truncated data) raise ``error``; pickled (object) arrays are never loaded.
    """
    try:
        fh = io.BytesIO(source) if isinstance(source, bytes | bytearray) else open(source, "rb")  # noqa: SIM115
    except OSError as exc:
        raise error(f"cannot read .npz: {exc}") from exc
    try:
        with fh, zipfile.ZipFile(fh) as zf:
            members = {info.filename.removesuffix(".npy"): info for info in zf.infolist()}
            headers = {n: _header(zf, members[n], n, error) for n in names if n in members}
            check(headers)
            out = {}
            for name, head in headers.items():
                if name in skip:
                    continue
                with zf.open(members[name]) as member:
                    arr = npy_format.read_array(member, allow_pickle=False)
                if arr.shape != head.shape or arr.dtype != head.dtype:
                    raise error(f"member {name!r} does not match its header")
                out[name] = arr
            return out
    except InputError:
        raise
    except MemoryError as exc:  # not bad input: the process's memory limit (CLI exit 4, job out_of_memory)
        from .outofmemory import out_of_memory

        raise out_of_memory(exc, "the .npz arrays do not fit in memory: use fewer frames or vertices, or "
                                 "raise the limit") from exc
    except _FAILURES as exc:
        raise error(f"not a valid .npz file ({type(exc).__name__}: {exc})") from exc


MAP_CHUNK_BYTES = 1 << 24
"""A member inflated into a file (:func:`mapped_member`) is read, checked and written this many bytes at a
time."""


def mapped_member(path: str | Path, name: str, check_chunk: Callable[[np.ndarray, int], None],
                  error: type[InputError] = InputError, tmp_dir: str | None = None,
                  into: Path | None = None) -> np.memmap | None:
    """Member ``name`` of the .npz at ``path`` as a read-only float32 array mapped from a file, so that its
    values live in the page cache rather than in this process's memory: the .npz itself where the member is
    stored uncompressed as little-endian float32, else an unlinked temporary file in ``tmp_dir`` that the
    member is inflated (and converted to float32) into, MAP_CHUNK_BYTES at a time. ``check_chunk`` sees every
    chunk of values as float32 with the flat index of its first (e.g. to refuse non-finite values). None
    where the member is not a
    C-ordered numeric array of 2 or more dimensions (read it with :func:`read_npz`). The caller checks the
    headers first (:func:`read_npz`'s ``check``); :func:`release_pages` drops what was read of it. ``into``:
    the values are always written to this file (raw float32, C order), which the caller then owns."""
    import tempfile

    try:
        with open(path, "rb") as fh, zipfile.ZipFile(fh) as zf:
            info = {i.filename.removesuffix(".npy"): i for i in zf.infolist()}[name]
            head = _header(zf, info, name, error)
            with zf.open(info) as member:
                version = npy_format.read_magic(member)
                read = (npy_format.read_array_header_1_0 if version == (1, 0)
                        else npy_format.read_array_header_2_0)
                shape, fortran, dtype = read(member)
                data_at = member.tell()
                if fortran or len(shape) < 2 or head.count == 0 or dtype.kind not in "fiu":
                    return None
                shape = tuple(int(s) for s in shape)
                if into is None and info.compress_type == zipfile.ZIP_STORED and dtype == np.dtype("<f4"):
                    fh.seek(info.header_offset + 26)
                    name_len, extra_len = np.frombuffer(fh.read(4), "<u2")
                    offset = info.header_offset + 30 + int(name_len) + int(extra_len) + data_at
                    _check_file_chunks(fh, offset, head.count, check_chunk)
                    return _map(fh.name, offset, shape)
                # kept open by the mapping
                out = tempfile.TemporaryFile(dir=tmp_dir) if into is None else open(into, "w+b")  # noqa: SIM115
                per = max(1, MAP_CHUNK_BYTES // dtype.itemsize)
                left = head.count
                while left:
                    n = min(per, left)
                    raw = member.read(n * dtype.itemsize)
                    if len(raw) != n * dtype.itemsize:
                        raise error(f"member {name!r} of the .npz ends before its data")
                    values = np.frombuffer(raw, dtype).astype(np.float32)
                    check_chunk(values, head.count - left)
                    out.write(values.tobytes())
                    left -= n
                out.flush()
                return _map(out, 0, shape)
    except InputError:
        raise
    except MemoryError as exc:
        from .outofmemory import out_of_memory

        raise out_of_memory(exc, "the .npz arrays do not fit in memory: use fewer frames or vertices, or "
                                 "raise the limit") from exc
    except _FAILURES as exc:
        raise error(f"not a valid .npz file ({type(exc).__name__}: {exc})") from exc


def _map(file, offset: int, shape: tuple[int, ...]) -> np.memmap:  # noqa: ANN001 - a path or an open file
    """A read-only float32 mapping of ``shape`` at ``offset`` of ``file``. A mapping counts against the
    address-space limit (RLIMIT_AS): where mmap fails for want of it (ENOMEM), a MemoryError that names the
    mapping's size, so the caller reports out of memory (CLI exit 4) rather than a bad file."""
    import errno

    try:
        return np.memmap(file, np.float32, "r", offset, shape)
    except OSError as exc:
        if exc.errno != errno.ENOMEM:
            raise
        failed = MemoryError(f"mapping {int(np.prod(shape)) * 4} bytes of poses: {exc}")
        failed.needed = int(np.prod(shape)) * 4
        raise failed from exc


def _check_file_chunks(fh, offset: int, count: int, check_chunk: Callable[[np.ndarray, int], None]) -> None:  # noqa: ANN001
    """``check_chunk`` on every MAP_CHUNK_BYTES of ``count`` float32 values at ``offset`` of ``fh``."""
    fh.seek(offset)
    per = MAP_CHUNK_BYTES // 4
    for start in range(0, count, per):
        values = np.fromfile(fh, np.float32, min(per, count - start))
        if len(values) != min(per, count - start):
            raise EOFError("the member ends before its data")
        check_chunk(values, start)


def release_pages(values: np.ndarray) -> None:
    """Drop from this process's resident memory the pages of a file-mapped array (:func:`mapped_member`) that
    were read so far (they stay in the page cache and are read again when touched); nothing for other
    arrays."""
    import mmap

    mm = getattr(values, "_mmap", None)
    if isinstance(mm, mmap.mmap) and hasattr(mm, "madvise"):
        mm.madvise(mmap.MADV_DONTNEED)
