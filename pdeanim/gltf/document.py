"""A parsed glTF 2.0 asset (GLB or .gltf JSON with embedded or neighbouring buffers) and accessor decoding:
strides, normalized integers, sparse substitution and view-less (all-zero) accessors."""

from __future__ import annotations

import base64
import binascii
import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np

from ..errors import InputError, LimitError, PosesInputError
from .glb import COMPONENT_DTYPES, GLB_MAGIC, TYPE_SIZES, split_glb

_NORM_DIVISOR = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
MAX_ACCESSOR_VALUES = 60_000_000  # cap on components of one accessor not backed by checked buffer data
MALFORMED = (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError, ZeroDivisionError,
             RecursionError, np.linalg.LinAlgError)
# required extensions that change how geometry is stored and that this reader cannot decode
UNSUPPORTED_GEOMETRY = ("KHR_meshopt_compression", "EXT_mesh_gpu_instancing")  # Draco: pdeanim.gltf.draco
MESHOPT = "EXT_meshopt_compression"  # decoded here (pdeanim.gltf.meshopt)
MAX_COUNT = 2**31 - 1  # glTF counts are 32-bit; a larger one is refused before anything is allocated


@dataclass(frozen=True)
class GltfLimits:
    """Explicit limits on what a glTF asset may declare, checked against the JSON before the work it
    declares is done (each names its service setting in the error)."""

    max_json_bytes: int = 32 * 1024**2
    max_json_depth: int = 64
    max_decoded_bytes: int = 1024**3  # decoded meshopt views + decoded accessors (float64), in total
    max_nodes: int = 20_000
    max_primitives: int = 20_000
    max_accessors: int = 100_000


def json_depth(raw: bytes) -> int:
    """The deepest nesting of arrays and objects in JSON text (brackets inside strings ignored), found with
    a few vectorised passes instead of a recursive parser (Python's json module raises RecursionError past
    about 1,000 levels)."""
    text = np.frombuffer(raw, np.uint8)
    at = np.flatnonzero((text == ord('"')) | (text == ord("\\")))  # quotes and backslashes, in order
    quotes = at[text[at] == ord('"')]
    if len(at) > len(quotes):  # a quote after an odd run of backslashes is escaped: drop it
        index = np.arange(len(text))
        last_plain = np.maximum.accumulate(np.where(text != ord("\\"), index, -1))
        run = quotes - 1 - last_plain[np.maximum(quotes - 1, 0)]
        quotes = quotes[(run % 2 == 0) | (quotes == 0)]
    folded = text | 0x20  # "[" -> "{" and "]" -> "}" (no other byte folds onto them)
    brackets = np.flatnonzero((folded == ord("{")) | (folded == ord("}")))
    outside = np.searchsorted(quotes, brackets) % 2 == 0  # an even number of quotes before it
    kind = text[brackets[outside]]
    steps = np.where((kind == ord("[")) | (kind == ord("{")), 1, -1)
    return int(np.cumsum(steps).max()) if steps.size else 0


def parse_json(raw: bytes, limits: GltfLimits, error: type[InputError]) -> dict[str, Any]:
    """The glTF JSON object of ``raw``, after its size and nesting depth were checked against ``limits``."""
    if len(raw) > limits.max_json_bytes:
        raise LimitError("glTF JSON size in bytes", len(raw), limits.max_json_bytes,
                         "PDEANIM_MAX_GLTF_JSON_BYTES")
    depth = json_depth(raw)
    if depth > limits.max_json_depth:
        raise LimitError("glTF JSON nesting depth", depth, limits.max_json_depth,
                         "PDEANIM_MAX_GLTF_JSON_DEPTH")
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise error(f"not a glTF file (its JSON does not parse): {exc}") from exc
    if not isinstance(doc, dict):
        raise error("glTF JSON must be an object")
    return doc


@contextmanager
def malformed_as(error: type[InputError]) -> Iterator[None]:
    """Turn the lookup and type errors a malformed glTF JSON provokes into ``error`` (an InputError)."""
    try:
        yield
    except InputError:
        raise
    except MALFORMED as exc:
        raise error(f"malformed glTF ({type(exc).__name__}: {exc})") from exc


class GltfDocument:
    """The JSON of a glTF asset with its buffers loaded; ``error`` is the InputError class raised on
    defects."""

    def __init__(self, doc: dict[str, Any], buffers: list[bytes], error: type[InputError] = PosesInputError,
                 limits: GltfLimits | None = None):
        self.doc, self.buffers, self.error = doc, buffers, error
        self.limits = limits or GltfLimits()
        self.decoded_bytes = 0  # what decoding this document has allocated so far (capped by limits)
        self._decoded: dict[int, bytes] = {}
        self._draco_streams: dict[int, Any] = {}
        from .draco import draco_accessors

        self.draco = draco_accessors(doc)  # accessor -> (Draco stream's bufferView, attribute id)
        version = str(doc.get("asset", {}).get("version", ""))
        if not version.startswith("2."):
            raise error(f"unsupported glTF version {version!r} (need 2.x)")
        blocked = sorted(set(doc.get("extensionsRequired", [])) & set(UNSUPPORTED_GEOMETRY))
        if blocked:
            raise error(
                f"the glTF file needs {', '.join(blocked)} to decode its geometry, which pdeanim does "
                f"not read; export it without mesh compression"
            )

    def spend(self, nbytes: int, what: str) -> None:
        """Count ``nbytes`` about to be decoded for ``what``; LimitError before allocating past the cap."""
        if self.decoded_bytes + nbytes > self.limits.max_decoded_bytes:
            raise LimitError(f"decoded size of the glTF data in bytes (with {what} of {nbytes})",
                             self.decoded_bytes + nbytes, self.limits.max_decoded_bytes,
                             "PDEANIM_MAX_DECODED_BYTES")
        self.decoded_bytes += nbytes

    def list(self, key: str) -> list[dict[str, Any]]:
        """A top-level array of the document (``nodes``, ``meshes``...), empty when absent."""
        value = self.doc.get(key, [])
        return value if isinstance(value, list) else []

    def item(self, key: str, index: Any) -> dict[str, Any]:
        """``doc[key][index]`` or a clear error naming the dangling reference."""
        items = self.list(key)
        if not isinstance(index, int) or not 0 <= index < len(items):
            raise self.error(f"glTF refers to {key}[{index}], which does not exist ({len(items)} present)")
        return items[index]

    def accessor(self, index: int) -> np.ndarray:
        """Decode accessor ``index`` to (count, components) float64 (normalized ints scaled) or int64."""
        acc = self.item("accessors", index)
        try:
            ctype, count, width = int(acc["componentType"]), int(acc["count"]), TYPE_SIZES[acc["type"]]
            dtype = COMPONENT_DTYPES[ctype]
        except (KeyError, TypeError, ValueError) as exc:
            raise self.error(f"accessor {index} is malformed: {exc}") from exc
        if count < 0 or count > MAX_COUNT or count * width > MAX_ACCESSOR_VALUES:
            raise self.error(f"accessor {index} has an implausible count {count}")
        self.spend(count * width * 8, f"accessor {index}")  # the float64/int64 result
        if index in self.draco:
            data = self.draco_values(index)
        elif "bufferView" in acc:
            data = self._strided(acc.get("bufferView"), int(acc.get("byteOffset", 0)), count, width, dtype)
        else:
            data = np.zeros((count, width), dtype)
        if "sparse" in acc:
            data = self._sparse(acc["sparse"], data, width, dtype, index)
        if ctype == 5126:
            return data.astype(np.float64)
        if acc.get("normalized"):
            return np.maximum(data.astype(np.float64) / _NORM_DIVISOR[ctype], -1.0)
        return data.astype(np.int64)

    def matrices(self, index: int) -> np.ndarray:
        """A MAT4 accessor as (count, 4, 4) float64 matrices (glTF stores them column-major)."""
        return self.accessor(index).reshape(-1, 4, 4).transpose(0, 2, 1)

    def _strided(self, view_index: Any, offset: int, count: int, width: int, dtype: np.dtype) -> np.ndarray:
        view = self.item("bufferViews", view_index)
        ext = (view.get("extensions") or {}).get(MESHOPT)
        if ext is not None:
            buf, start = self._meshopt_view(view_index, view, ext), offset
        else:
            index = view.get("buffer", 0)
            buf = self.buffers[index] if 0 <= index < len(self.buffers) else None
            if buf is None:
                raise self.error(f"bufferView {view_index} refers to a missing buffer")
            start = int(view.get("byteOffset", 0)) + offset
        elem = width * dtype.itemsize
        stride = int(view.get("byteStride", elem))
        need = (count - 1) * stride + elem if count else 0
        if start < 0 or offset + need > int(view.get("byteLength", 0)) or start + need > len(buf):
            raise self.error(f"an accessor on bufferView {view_index} runs past the end of its data")
        if count == 0:
            return np.zeros((0, width), dtype)
        rows = np.lib.stride_tricks.as_strided(np.frombuffer(buf, np.uint8, need, start), (count, elem),
                                               (stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)

    def view_bytes(self, index: int) -> bytes:
        """The (decoded) bytes of buffer view ``index``."""
        view = self.item("bufferViews", index)
        ext = (view.get("extensions") or {}).get(MESHOPT)
        if ext is not None:
            return self._meshopt_view(index, view, ext)[: int(view.get("byteLength", 0))]
        buffer = view.get("buffer", 0)
        if not isinstance(buffer, int) or not 0 <= buffer < len(self.buffers):
            raise self.error(f"bufferView {index} refers to a missing buffer")
        start = int(view.get("byteOffset", 0))
        data = self.buffers[buffer][start: start + int(view.get("byteLength", 0))]
        if len(data) != int(view.get("byteLength", 0)):
            raise self.error(f"bufferView {index} runs past the end of its buffer")
        return data

    def _meshopt_view(self, index: int, view: dict, ext: dict) -> bytes:
        """The decoded bytes of an EXT_meshopt_compression view (decoded once, then kept)."""
        if index not in self._decoded:
            from .meshopt import decode_view

            if not 0 <= int(ext.get("buffer", 0)) < len(self.buffers):
                raise self.error(f"compressed bufferView {index} refers to a missing buffer")
            self.spend(meshopt_size(ext, index, self.error), f"compressed bufferView {index}")
            try:
                data = decode_view(ext, self.buffers)
            except (RuntimeError, ValueError, KeyError) as exc:
                raise self.error(f"cannot decode compressed bufferView {index}: {exc}") from exc
            if len(data) < int(view.get("byteLength", 0)):
                raise self.error(f"compressed bufferView {index} decodes to fewer bytes than its byteLength")
            self._decoded[index] = data
        return self._decoded[index]

    def draco_values(self, index: int) -> np.ndarray:
        """The (count, components) values of accessor ``index`` from its KHR_draco_mesh_compression stream in
        the accessor's component type (the stream is decoded once, after its declared size is counted)."""
        from .draco import decode_stream, stream_values

        acc = self.item("accessors", index)
        view, uid = self.draco[index]
        if view not in self._draco_streams:
            parts = [self.item("accessors", a) for a, (v, _) in self.draco.items() if v == view]
            declared = sum(int(p["count"]) * TYPE_SIZES[p["type"]] * 4 for p in parts)
            self.spend(declared, f"Draco stream in bufferView {view}")
            try:
                self._draco_streams[view] = decode_stream(self.view_bytes(view))
            except ValueError as exc:
                raise self.error(f"cannot decode the Draco stream in bufferView {view}: {exc}") from exc
        dtype = COMPONENT_DTYPES[int(acc["componentType"])]
        try:
            data = stream_values(self._draco_streams[view], uid, int(acc["count"]), TYPE_SIZES[acc["type"]])
        except ValueError as exc:
            raise self.error(f"accessor {index}: {exc}") from exc
        if np.issubdtype(data.dtype, np.floating) and not np.issubdtype(dtype, np.floating):
            scale = _NORM_DIVISOR.get(int(acc["componentType"]), 1.0) if acc.get("normalized") else 1.0
            data = np.rint(data * scale)
        return data.astype(dtype)

    def _sparse(self, sparse: dict, data: np.ndarray, width: int, dtype: np.dtype, index: int) -> np.ndarray:
        try:
            n = int(sparse["count"])
            ind, val = sparse["indices"], sparse["values"]
            idx = self._strided(ind["bufferView"], int(ind.get("byteOffset", 0)), n, 1,
                                COMPONENT_DTYPES[int(ind["componentType"])])[:, 0].astype(np.int64)
            values = self._strided(val["bufferView"], int(val.get("byteOffset", 0)), n, width, dtype)
        except (KeyError, TypeError, ValueError) as exc:
            raise self.error(f"sparse accessor {index} is malformed: {exc}") from exc
        if n and (idx.min() < 0 or idx.max() >= len(data)):
            raise self.error(f"sparse accessor {index} has indices out of range")
        out = data.copy()
        out[idx] = values
        return out


def meshopt_size(ext: dict, index: int, error: type[InputError]) -> int:
    """Bytes an EXT_meshopt_compression view declares it decodes to (count x byteStride), after checking
    that count and stride are ones the spec allows."""
    try:
        count, stride, mode = int(ext["count"]), int(ext["byteStride"]), ext.get("mode")
    except (KeyError, TypeError, ValueError) as exc:
        raise error(f"compressed bufferView {index} is malformed: {exc}") from exc
    if not 0 <= count <= MAX_COUNT:
        raise error(f"compressed bufferView {index} declares count {count}, outside [0, {MAX_COUNT}]")
    strides = range(4, 257, 4) if mode == "ATTRIBUTES" else (2, 4)
    if stride not in strides:
        raise error(f"compressed bufferView {index} ({mode}) has byteStride {stride}, which the "
                    "EXT_meshopt_compression spec does not allow")
    return count * stride


def _buffer_bytes(
    buf: dict, index: int, glb_bin: bytes | None, base: Path | None, error: type[InputError]
) -> bytes:
    uri = buf.get("uri")
    if uri is None:
        if index == 0 and glb_bin is not None:
            return glb_bin
        if ((buf.get("extensions") or {}).get(MESHOPT) or {}).get("fallback"):
            return b""  # a fallback buffer of EXT_meshopt_compression: its views are decoded instead
        raise error(f"buffer {index} has no data (no uri and no GLB binary chunk)")
    if uri.startswith("data:"):
        head, _, payload = uri.partition(",")
        if not head.endswith(";base64"):
            raise error(f"buffer {index} has a data URI that is not base64")
        try:
            return base64.b64decode(payload, validate=True)
        except binascii.Error as exc:
            raise error(f"buffer {index} has invalid base64 data: {exc}") from exc
    if base is None:
        raise error(f"buffer {index} refers to an external file {uri!r}; upload a GLB or embedded .gltf")
    path = (base / unquote(uri)).resolve()
    if base.resolve() not in path.parents:
        raise error(f"buffer {index} refers to a file outside the asset's folder: {uri!r}")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise error(f"cannot read buffer {index} from {uri!r}: {exc}") from exc


def load_document(source: str | Path | bytes, error: type[InputError] = PosesInputError,
                  limits: GltfLimits | None = None) -> GltfDocument:
    """Parse GLB or .gltf (path or bytes); external buffers are read only next to a file given by path.
    The JSON's size and depth are checked against ``limits`` before it is parsed."""
    limits = limits or GltfLimits()
    base = None
    if isinstance(source, bytes | bytearray | memoryview):
        data = bytes(source)
    else:
        try:
            data = Path(source).read_bytes()
        except OSError as exc:
            raise error(f"cannot read glTF file {source}: {exc}") from exc
        base = Path(source).parent
    if data[:4] == GLB_MAGIC:
        try:
            raw, glb_bin = split_glb(data)
        except LimitError:
            raise
        except InputError as exc:
            raise error(str(exc)) from exc
    else:
        raw, glb_bin = data, None
    doc = parse_json(raw, limits, error)
    with malformed_as(error):
        buffers = [_buffer_bytes(b, i, glb_bin, base, error) for i, b in enumerate(doc.get("buffers", []))]
        return GltfDocument(doc, buffers, error, limits)
