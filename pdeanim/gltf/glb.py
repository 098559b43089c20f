"""GLB container and glTF buffer bookkeeping: build a JSON document with one binary buffer of 4-byte aligned
buffer views and accessors, and split GLB bytes back into JSON and BIN chunks."""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np

from ..errors import InputError

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

# numpy dtype <-> glTF componentType
COMPONENT_TYPES = {np.dtype(np.int8): 5120, np.dtype(np.uint8): 5121, np.dtype(np.int16): 5122,
                   np.dtype(np.uint16): 5123, np.dtype(np.uint32): 5125, np.dtype(np.float32): 5126}
COMPONENT_DTYPES = {v: k.newbyteorder("<") for k, v in COMPONENT_TYPES.items()}
TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TYPE_OF_WIDTH = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


def _pad4(n: int) -> int:
    return (n + 3) // 4 * 4


def json_float(x: np.floating | float) -> float:
    """A float32 value as the Python float that prints (and parses back) as exactly that float32."""
    return float(np.float32(x))


class GlbBuilder:
    """Accumulates buffer views and accessors of one binary buffer and the glTF JSON around them."""

    def __init__(self, generator: str = "pdeanim") -> None:
        self.doc: dict[str, Any] = {"asset": {"version": "2.0", "generator": generator},
                                    "bufferViews": [], "accessors": []}
        self._chunks: list[bytes] = []
        self._length = 0

    def add_view(self, raw: bytes, target: int | None = None, stride: int | None = None) -> int:
        """Append ``raw`` as a buffer view starting on a 4-byte boundary; returns its index."""
        view: dict[str, Any] = {"buffer": 0, "byteOffset": self._length, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        if stride is not None:
            view["byteStride"] = stride
        padded = _pad4(len(raw))
        self._chunks.append(raw + b"\0" * (padded - len(raw)))
        self._length += padded
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def add_accessor(self, data: np.ndarray, *, target: int | None = None, normalized: bool = False,
                     minmax: bool = False, acc_type: str | None = None, stride_pad: int = 0) -> int:
        """Append an accessor over ``data`` (N,) or (N, k) with its own view; ``stride_pad`` extra zero
        components per element keep vertex attributes 4-byte aligned (e.g. SHORT VEC3 -> stride 8)."""
        a = np.asarray(data)
        dtype = a.dtype.newbyteorder("<")
        a2 = a.reshape(len(a), -1)
        width = a2.shape[1]
        stride = None
        if stride_pad:
            a2 = np.concatenate([a2, np.zeros((len(a2), stride_pad), a2.dtype)], axis=1)
            stride = a2.shape[1] * dtype.itemsize
        view = self.add_view(np.ascontiguousarray(a2, dtype=dtype).tobytes(), target, stride)
        acc: dict[str, Any] = {"bufferView": view, "componentType": COMPONENT_TYPES[np.dtype(a.dtype)],
                               "count": int(len(a)), "type": acc_type or _TYPE_OF_WIDTH[width]}
        if normalized:
            acc["normalized"] = True
        if minmax:
            acc.update(bounds(a.reshape(len(a), width)))
        return self._push(acc)

    def add_zero_accessor(self, count: int, acc_type: str = "VEC3") -> int:
        """An all-zero float accessor without a buffer view (the spec initialises it with zeros)."""
        n = TYPE_SIZES[acc_type]
        return self._push({"componentType": 5126, "count": int(count), "type": acc_type,
                           "min": [0.0] * n, "max": [0.0] * n})

    def _push(self, acc: dict[str, Any]) -> int:
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def to_glb(self) -> bytes:
        """The finished GLB: header, space-padded JSON chunk, zero-padded BIN chunk (omitted when empty)."""
        doc = dict(self.doc)
        if self._length:
            doc["buffers"] = [{"byteLength": self._length}]
        for key in ("bufferViews", "accessors"):
            if not doc[key]:
                del doc[key]
        return _pack(doc, self._chunks, self._length)


def bounds(a: np.ndarray) -> dict[str, list]:
    """Exact per-component ``min``/``max`` of (N, k) data as JSON lists (float32 or integers)."""
    lo, hi = a.min(axis=0), a.max(axis=0)
    if np.issubdtype(a.dtype, np.floating):
        return {"min": [json_float(x) for x in lo], "max": [json_float(x) for x in hi]}
    return {"min": [int(x) for x in lo], "max": [int(x) for x in hi]}


def pack_glb(doc: dict[str, Any], binary: bytes) -> bytes:
    """GLB bytes of a glTF JSON document and its binary buffer, both chunks padded to 4 bytes."""
    return _pack(doc, [binary], len(binary))


def _pack(doc: dict[str, Any], parts: list[bytes], length: int) -> bytes:
    """GLB bytes of ``doc`` and a binary buffer given as ``parts`` of ``length`` bytes in total, joined
    with one copy (large animations are tens of MB)."""
    js = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode("utf-8")
    js += b" " * (_pad4(len(js)) - len(js))
    out = [b"", struct.pack("<II", len(js), CHUNK_JSON), js]
    if length:
        padded = _pad4(length)
        out += [struct.pack("<II", padded, CHUNK_BIN), *parts, b"\0" * (padded - length)]
    out[0] = struct.pack("<4sII", GLB_MAGIC, 2, sum(len(x) for x in out) + 12)
    return b"".join(out)


def unpack_glb(data: bytes) -> tuple[dict[str, Any], bytes | None]:
    """Split GLB bytes into the parsed JSON document and the BIN chunk (None when absent)."""
    raw, binary = split_glb(data)
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"GLB JSON chunk is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise InputError("GLB has no JSON chunk")
    return doc, binary


def split_glb(data: bytes) -> tuple[bytes, bytes | None]:
    """Split GLB bytes into the raw JSON chunk (not parsed: the caller checks its size and depth first) and
    the BIN chunk (None when absent)."""
    if len(data) < 20 or data[:4] != GLB_MAGIC:
        raise InputError("not a GLB file (missing 'glTF' magic)")
    _, version, length = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise InputError(f"unsupported GLB version {version} (need 2)")
    if length > len(data):
        raise InputError(f"GLB is truncated: header says {length} bytes, got {len(data)}")
    doc, binary, pos = None, None, 12
    while pos + 8 <= length:
        size, kind = struct.unpack_from("<II", data, pos)
        chunk = data[pos + 8: pos + 8 + size]
        if len(chunk) != size:
            raise InputError("GLB chunk runs past the end of the file")
        if kind == CHUNK_JSON and doc is None:
            doc = bytes(chunk)
        elif kind == CHUNK_BIN and binary is None:
            binary = bytes(chunk)
        pos += 8 + _pad4(size)
    if doc is None:
        raise InputError("GLB has no JSON chunk")
    return doc, binary
