"""The binary container every pdeanim blob uses: a small JSON header plus little-endian arrays.

Layout, all integers little-endian::

    0   8 bytes   magic b"PDEANIM\\0"
    8   uint32    container version, 1
    12  uint32    H, length of the JSON header in bytes (UTF-8, space-padded to a multiple of 8)
    16  H bytes   JSON header: {"part": ..., ..., "arrays": {name: {"dtype", "shape", "offset", "nbytes"}}}
    16+H          array data; each array starts at ``offset`` bytes after the data start, 8-byte aligned

Arrays are C-ordered with dtypes from ALLOWED_DTYPES. An array may carry an ``"encoding"``:
``"zstd"`` (the stored bytes are one zstd frame of the array's bytes) or ``"shuffle-zstd"`` (the same, of the
array's bytes grouped by byte plane: byte j of element i at j * n + i); ``nbytes`` is then the stored
size. The JSON form (for debugging) is the same header with each array's values inlined as a flat list
under "data" instead of offset/nbytes (and no encoding).
"""

from __future__ import annotations

import json
import math
import os
import struct
import tempfile
from collections.abc import Collection, Iterator
from typing import IO, Any

import numpy as np

from .errors import ClipFormatError

MAGIC = b"PDEANIM\0"
VERSION = 1
ENCODINGS = ("zstd", "shuffle-zstd")
SMALLEST = "smallest"
"""Writer's choice (never stored): whichever of ENCODINGS gives fewer bytes for the array; arrays of at least
CHOICE_BYTES are compared at CHOICE_LEVEL and only the chosen encoding is compressed at the writer's level."""
ZSTD_LEVEL = 19
CHOICE_LEVEL = 3
CHOICE_BYTES = 1 << 18
"""SMALLEST compares the encodings of arrays this large at CHOICE_LEVEL: a level-19 pass costs ~20x a level-3
one, and on large arrays the two levels rarely pick differently (one of 15 arrays of an elephant-gallop clip,
272 bytes of 1.06 MB). On small ones they can (the rest positions of AnimatedMorphSphere: 1,393 bytes as
picked at level 3, 1,151 at level 19), and compressing both at the final level costs little."""
MAX_EXPANSION = 1024
EXPANSION_FLOOR = 64 << 20
"""Readers refuse a container whose arrays declare more than ``max(MAX_EXPANSION x its size,
EXPANSION_FLOOR)`` bytes in all once decoded, before decoding any: a small file must not make a reader
allocate gigabytes (zstd packs 4 GiB of zeros into 131 KB). Measured on 250 parts of real clips: at most 47x
(the topology of a 34k-vertex fit, 227 KB -> 10.6 MB); 10x is common."""
MAX_DECODED_BYTES = 8 * 1024**3
"""... and whatever their size, never more than this (the default of :func:`unpack`'s cap)."""
FEED = 512  # compressed bytes per decompression call when spooling: bounds one call's output (zstd blocks
# decode to at most 128 KiB each)
SPOOL_BYTES = 4 << 20  # iter_json decodes arrays up to this in memory, larger ones through a scratch file
ALLOWED_DTYPES = ("<f4", "<f8", "<i4", "<u4", "<i2", "<u2", "<u1", "<i1")
_PREFIX = struct.Struct("<8sII")


def _pad8(n: int) -> int:
    return (n + 7) // 8 * 8


def _canonical(arr: np.ndarray) -> np.ndarray:
    a = np.asarray(arr)
    dt = a.dtype.newbyteorder("<") if a.dtype.byteorder not in ("<", "|", "=") else a.dtype
    a = np.ascontiguousarray(a, dtype=dt)
    if a.dtype.str not in ALLOWED_DTYPES and a.dtype.str.replace("|", "<") not in ALLOWED_DTYPES:
        raise ValueError(f"dtype {a.dtype} is not allowed in a pdeanim container")
    return a


def pack(header: dict[str, Any], arrays: dict[str, np.ndarray],
         encodings: dict[str, str] | None = None, level: int = ZSTD_LEVEL) -> bytes:
    """Encode ``header`` (JSON-able, without "arrays") and named arrays into container bytes; arrays named
    in ``encodings`` are stored compressed (``"zstd"``, ``"shuffle-zstd"`` or SMALLEST of the two) at zstd
    ``level``."""
    encodings = encodings or {}
    table: dict[str, dict] = {}
    chunks: list[bytes] = []
    offset = 0
    for name, arr in arrays.items():
        a = _canonical(arr)
        entry = {"dtype": a.dtype.str.replace("|", "<"), "shape": list(a.shape), "offset": offset}
        if name in encodings:
            raw, entry["encoding"] = _encode_chosen(a, encodings[name], level)
        else:
            raw = a.tobytes()
        entry["nbytes"] = len(raw)
        table[name] = entry
        chunks.append(raw + b"\0" * (_pad8(len(raw)) - len(raw)))
        offset += _pad8(len(raw))
    try:
        meta = json.dumps({**header, "arrays": table}, separators=(",", ":"), sort_keys=True,
                          allow_nan=False).encode()
    except ValueError as exc:
        raise ValueError(f"container header must not hold NaN or infinity (use null): {exc}") from exc
    meta += b" " * (_pad8(len(meta)) - len(meta))
    return _PREFIX.pack(MAGIC, VERSION, len(meta)) + meta + b"".join(chunks)


def _encode_chosen(a: np.ndarray, encoding: str, level: int) -> tuple[bytes, str]:
    """(stored bytes, encoding) of array ``a`` under ``encoding`` or, for SMALLEST, under the encoding that
    compresses smaller (at CHOICE_LEVEL for arrays of CHOICE_BYTES or more)."""
    if encoding != SMALLEST:
        return _encode(a, encoding, level), encoding
    trial_level = min(level, CHOICE_LEVEL) if a.nbytes >= CHOICE_BYTES else level
    trials = [(_encode(a, e, trial_level), e) for e in ENCODINGS]
    raw, chosen = min(trials, key=lambda c: len(c[0]))
    return (raw if trial_level == level else _encode(a, chosen, level)), chosen


def _encode(a: np.ndarray, encoding: str, level: int = ZSTD_LEVEL) -> bytes:
    """The stored bytes of array ``a`` under ``encoding`` (deterministic: same array, same bytes)."""
    import zstandard

    if encoding not in ENCODINGS:
        raise ValueError(f"unknown container encoding {encoding!r} (known: {', '.join(ENCODINGS)})")
    flat = a.reshape(-1).view(np.uint8)  # the canonical array's bytes, not a copy
    raw = flat.reshape(-1, a.dtype.itemsize).T.tobytes() if encoding == "shuffle-zstd" else flat.data
    writer = zstandard.ZstdCompressor(level=level, write_content_size=True, write_checksum=True)
    return writer.compress(raw)


def decode_array(stored: bytes, encoding: str, dtype: np.dtype, count: int, name: str) -> np.ndarray:
    """The flat array of ``count`` elements behind ``stored`` bytes; raises ClipFormatError."""
    import zstandard

    if encoding not in ENCODINGS:
        raise ClipFormatError(f"array {name!r} has an unknown encoding {encoding!r}")
    size = count * dtype.itemsize
    try:
        declared = zstandard.frame_content_size(stored)
        if declared != size:  # writers record the size; checked before anything is allocated
            raise ClipFormatError(f"array {name!r}: zstd frame holds {declared} bytes, expected {size}")
        reader = zstandard.ZstdDecompressor().decompressobj()
        raw = reader.decompress(stored)
    except zstandard.ZstdError as exc:
        raise ClipFormatError(f"array {name!r}: bad zstd data ({exc})") from exc
    if not reader.eof or reader.unused_data:
        raise ClipFormatError(f"array {name!r}: the zstd data must be exactly one complete frame")
    if len(raw) != size:
        raise ClipFormatError(f"array {name!r} decompresses to {len(raw)} bytes, expected {size}")
    if encoding == "shuffle-zstd" and dtype.itemsize > 1:
        raw = np.frombuffer(raw, np.uint8).reshape(dtype.itemsize, count).T.tobytes()
    return np.frombuffer(raw, dtype=dtype, count=count)


def unpack(blob: bytes, max_decoded_bytes: int = MAX_DECODED_BYTES,
           names: Collection[str] | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Decode container bytes into (header, arrays); arrays are read-only views. Raises ClipFormatError, also
    when the arrays declare more than :func:`decoded_limit` bytes in total (checked before decoding).
    ``names``: decode only those arrays (the others are checked, not decoded)."""
    header, table = entries(blob, max_decoded_bytes)
    arrays: dict[str, np.ndarray] = {}
    for name, dtype, shape, lo, n, encoding, size in table:
        if names is not None and name not in names:
            continue
        count = size // dtype.itemsize
        if encoding is None:
            arrays[name] = np.frombuffer(blob, dtype=dtype, count=count, offset=lo).reshape(shape)
        else:
            flat = decode_array(bytes(blob[lo:lo + n]), str(encoding), dtype, count, name)
            arrays[name] = flat.reshape(shape)
    return header, arrays


def shapes(blob: bytes) -> tuple[dict[str, Any], dict[str, tuple[int, ...]]]:
    """(header, shape of every array) of container bytes, nothing decoded; raises ClipFormatError as
    :func:`unpack` would before decoding."""
    header, table = entries(blob)
    return header, {name: shape for name, _, shape, *_ in table}


def entries(blob: bytes, max_decoded_bytes: int = MAX_DECODED_BYTES) -> tuple[dict[str, Any], list[tuple]]:
    """(header, checked array entries) of container bytes: per array (name, dtype, shape, offset in the blob,
    stored bytes, encoding or None, decoded bytes); nothing decoded. Raises ClipFormatError."""
    if len(blob) < _PREFIX.size:
        raise ClipFormatError(f"blob of {len(blob)} bytes is too short to be a pdeanim container")
    magic, version, hlen = _PREFIX.unpack_from(blob, 0)
    if magic != MAGIC:
        raise ClipFormatError("not a pdeanim container (bad magic bytes)")
    if version != VERSION:
        raise ClipFormatError(f"unsupported container version {version} (this build reads {VERSION})")
    start = _PREFIX.size + hlen
    if start > len(blob):
        raise ClipFormatError("truncated container header")
    try:
        header = json.loads(bytes(blob[_PREFIX.size:start]).decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ClipFormatError(f"container header is not valid JSON: {exc}") from exc
    table = [_entry(name, spec, start, len(blob)) for name, spec in _array_table(header).items()]
    declared, limit = sum(size for *_, size in table), decoded_limit(len(blob), max_decoded_bytes)
    if declared > limit:
        raise ClipFormatError(
            f"the container's arrays declare {declared} bytes once decoded, more than {limit} for a "
            f"container of {len(blob)} bytes (at most {MAX_EXPANSION}x its size or {EXPANSION_FLOOR} bytes, "
            f"and never over {max_decoded_bytes}): a damaged or forged file")
    return header, table


def spool_array(stored: memoryview, encoding: str, dtype: np.dtype, count: int, name: str,
                scratch: str | None) -> IO[bytes]:
    """An unlinked scratch file (gone with the process, however it ends) holding the array's raw elements,
    decompressed (and un-shuffled) in bounded memory; the same checks as
    :func:`decode_array`."""
    import zstandard

    if encoding not in ENCODINGS:
        raise ClipFormatError(f"array {name!r} has an unknown encoding {encoding!r}")
    size = count * dtype.itemsize
    fh = tempfile.TemporaryFile(prefix="pdeanim-clip-", dir=scratch)
    try:
        declared = zstandard.frame_content_size(stored)
        if declared != size:
            raise ClipFormatError(f"array {name!r}: zstd frame holds {declared} bytes, expected {size}")
        reader, written = zstandard.ZstdDecompressor().decompressobj(), 0
        for a in range(0, len(stored), FEED):
            if reader.eof:
                raise ClipFormatError(f"array {name!r}: the zstd data must be exactly one complete frame")
            chunk = reader.decompress(stored[a:a + FEED])
            written += len(chunk)
            if written > size:
                raise ClipFormatError(f"array {name!r} decompresses to more than {size} bytes")
            fh.write(chunk)
        if not reader.eof or reader.unused_data or written != size:
            raise ClipFormatError(f"array {name!r}: the zstd data must be exactly one complete frame "
                                  f"of {size} bytes")
        fh.flush()
        if encoding == "shuffle-zstd" and dtype.itemsize > 1:
            return _unshuffle(fh, dtype.itemsize, count, scratch)
        return fh
    except zstandard.ZstdError as exc:
        fh.close()
        raise ClipFormatError(f"array {name!r}: bad zstd data ({exc})") from exc
    except BaseException:
        fh.close()
        raise


def _unshuffle(src: IO[bytes], itemsize: int, count: int, scratch: str | None,
               chunk: int = 1 << 20) -> IO[bytes]:
    """The scratch file of byte planes ``src`` (byte j of element i at j * count + i) as plain elements, a
    chunk of elements at a time, in a new unlinked scratch file; ``src`` is closed."""
    dst = tempfile.TemporaryFile(prefix="pdeanim-clip-", dir=scratch)
    try:
        for a in range(0, count, chunk):
            n = min(chunk, count - a)
            planes = np.empty((itemsize, n), np.uint8)
            for j in range(itemsize):
                planes[j] = np.frombuffer(os.pread(src.fileno(), n, j * count + a), np.uint8)
            dst.write(planes.T.tobytes())
        dst.flush()
    except BaseException:
        dst.close()
        raise
    finally:
        src.close()
    return dst


def decoded_limit(stored: int, cap: int = MAX_DECODED_BYTES) -> int:
    """The most bytes a container of ``stored`` bytes may declare for its decoded arrays: MAX_EXPANSION times
    its size (at least EXPANSION_FLOOR), and never more than ``cap``."""
    return min(max(MAX_EXPANSION * stored, EXPANSION_FLOOR), cap)


def _array_table(header: dict[str, Any]) -> dict[str, Any]:
    """The header's ``arrays`` entry (removed from ``header``); ClipFormatError unless it is an object."""
    table = header.pop("arrays", {}) if isinstance(header, dict) else None
    if not isinstance(table, dict):
        raise ClipFormatError("container header must be a JSON object with an 'arrays' object")
    return table


def _entry(name: str, spec: Any, start: int, total: int) -> tuple:
    """(name, dtype, shape, offset, stored bytes, encoding, decoded bytes) of one array entry, checked
    against the container's size; raises ClipFormatError."""
    try:
        dtype = np.dtype(spec["dtype"])
        shape = tuple(int(s) for s in spec["shape"])
        lo, n = start + int(spec["offset"]), int(spec["nbytes"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ClipFormatError(f"bad array entry {name!r} in container header") from exc
    encoding = spec.get("encoding")
    if "encoding" in spec and not isinstance(encoding, str):
        raise ClipFormatError(f"array {name!r} has an unknown encoding {encoding!r}")
    size = math.prod(shape) * dtype.itemsize  # Python integers: a forged shape cannot wrap around
    if spec["dtype"] not in ALLOWED_DTYPES or min(shape, default=0) < 0 or n < 0 or (
            encoding is None and n != size):
        raise ClipFormatError(f"array {name!r} has an inconsistent dtype or size")
    if lo < start or lo + n > total:
        raise ClipFormatError(f"array {name!r} lies outside the container (truncated file?)")
    return name, dtype, shape, lo, n, encoding, size


def read_header(blob: bytes) -> dict[str, Any]:
    """The JSON header of container bytes without decoding any array (its ``arrays`` table removed); raises
    ClipFormatError as :func:`unpack` does for a damaged prefix or header."""
    if len(blob) < _PREFIX.size:
        raise ClipFormatError(f"blob of {len(blob)} bytes is too short to be a pdeanim container")
    magic, version, hlen = _PREFIX.unpack_from(blob, 0)
    if magic != MAGIC or version != VERSION or _PREFIX.size + hlen > len(blob):
        raise ClipFormatError("not a pdeanim container of version 1 (bad magic, version or header length)")
    try:
        header = json.loads(bytes(blob[_PREFIX.size:_PREFIX.size + hlen]).decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ClipFormatError(f"container header is not valid JSON: {exc}") from exc
    _array_table(header)
    return header


def array_encodings(blob: bytes) -> dict[str, str]:
    """The encoding of every compressed array of container bytes (to pack its arrays again the same way)."""
    magic, version, hlen = _PREFIX.unpack_from(blob, 0)
    table = json.loads(bytes(blob[_PREFIX.size:_PREFIX.size + hlen]).decode()).get("arrays", {})
    return {name: spec["encoding"] for name, spec in table.items() if "encoding" in spec}


def with_header(blob: bytes, extra: dict[str, Any]) -> bytes:
    """The container ``blob`` with keys added to its JSON header (the arrays' bytes untouched: their offsets
    count from the start of the data, which follows the header)."""
    magic, version, hlen = _PREFIX.unpack_from(blob, 0)
    header = json.loads(bytes(blob[_PREFIX.size:_PREFIX.size + hlen]).decode())
    header.update(extra)
    meta = json.dumps(header, separators=(",", ":"), sort_keys=True, allow_nan=False).encode()
    meta += b" " * (-len(meta) % 8)
    return _PREFIX.pack(magic, version, len(meta)) + meta + bytes(blob[_PREFIX.size + hlen:])


def to_json(blob: bytes) -> dict[str, Any]:
    """The JSON form of a container: its header with arrays inlined (dtype, shape, flat data)."""
    header, arrays = unpack(blob)
    header["arrays"] = {name: {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.ravel().tolist()}
                        for name, a in arrays.items()}
    return {"container": "pdeanim", "version": VERSION, **header}  # arrays inlined: nothing is encoded


def iter_json(blob: bytes, chunk: int = 1 << 16) -> Iterator[bytes]:
    """``json.dumps(to_json(blob)).encode()`` in pieces: one array decoded at a time and its values written
    ``chunk`` at a time, so the text is never held whole (nor the arrays as Python lists)."""
    header, table = entries(blob)
    head = json.dumps({"container": "pdeanim", "version": VERSION, **header})
    yield (head[:-1] + ', "arrays": {').encode()
    for i, (name, dtype, shape, lo, n, encoding, size) in enumerate(table):
        spec = json.dumps({"dtype": dtype.str, "shape": list(shape)})
        yield f'{", " if i else ""}{json.dumps(name)}: {spec[:-1]}, "data": ['.encode()
        count = size // dtype.itemsize
        if encoding is None or size <= SPOOL_BYTES:
            flat = unpack(blob, names=(name,))[1][name].ravel()
            values = (flat[a:a + chunk] for a in range(0, count, chunk))
        else:  # decompressed to a scratch file, read back a chunk of values at a time
            spooled = spool_array(memoryview(blob)[lo:lo + n], str(encoding), dtype, count, name, None)
            values = _spooled_chunks(spooled, dtype, count, chunk)
        for k, part in enumerate(values):
            yield ((", " if k else "") + json.dumps(part.tolist())[1:-1]).encode()
        yield b"]}"
    yield b"}}"


def _spooled_chunks(fh: IO[bytes], dtype: np.dtype, count: int, chunk: int) -> Iterator[np.ndarray]:
    """The elements of a spooled array (:func:`spool_array`), ``chunk`` at a time; then the file is closed."""
    with fh:
        for a in range(0, count, chunk):
            n = min(chunk, count - a)
            yield np.frombuffer(os.pread(fh.fileno(), n * dtype.itemsize, a * dtype.itemsize), dtype)


def from_json(doc: dict[str, Any]) -> bytes:
    """Inverse of :func:`to_json`: rebuild the binary container from its JSON form."""
    try:
        header = {k: v for k, v in doc.items() if k not in ("container", "version", "arrays")}
        arrays = {name: np.asarray(spec["data"], dtype=np.dtype(spec["dtype"])).reshape(spec["shape"])
                  for name, spec in doc.get("arrays", {}).items()}
    except (KeyError, TypeError, ValueError) as exc:
        raise ClipFormatError(f"bad JSON container: {exc}") from exc
    return pack(header, arrays)
