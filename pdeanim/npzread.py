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
             error: type[InputError] = InputError) -> dict[str, np.ndarray]:
    """The members ``names`` (without ``.npy``) of an .npz that exist, after ``check`` accepted their headers.

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
