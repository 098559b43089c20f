"""EXT_meshopt_compression for GLB (PyPI ``meshoptimizer``): compress the buffer views of a finished glTF
document (vertex attributes, morph targets and animation data as ATTRIBUTES streams, triangle indices as
TRIANGLES streams), and decode such views when reading. Lossless: it only re-encodes bytes.

The written layout follows the extension's spec: the compressed streams live in buffer 0 (the GLB BIN
chunk); each compressed view points, in the core JSON, into buffer 1, a fallback buffer without data
marked ``{"EXT_meshopt_compression": {"fallback": true}}``; the extension is used and required.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .glb import COMPONENT_DTYPES, TYPE_SIZES, pack_glb

EXT = "EXT_meshopt_compression"
VERTEX_CODEC_VERSION = 0  # the EXT_ extension allows version 0 of the vertex codec only
MIN_COMPRESSED_BYTES = 64  # smaller views stay raw: a stream header would cost more than it saves


def _pad4(n: int) -> int:
    return (n + 3) // 4 * 4


def _view_uses(doc: dict) -> dict[int, dict[str, Any]]:
    """Per buffer view: the element size its accessors agree on (None if they disagree), and whether it holds
    triangle-list indices or image data."""
    uses: dict[int, dict[str, Any]] = {}
    triangle_indices = set()
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            if "indices" in prim and prim.get("mode", 4) == 4:
                triangle_indices.add(prim["indices"])
    for i, acc in enumerate(doc.get("accessors", [])):
        for part in ("indices", "values"):  # sparse substitutions stay raw (rare, small)
            view = acc.get("sparse", {}).get(part, {}).get("bufferView")
            if view is not None:
                uses.setdefault(view, {})["raw"] = True
        if "bufferView" not in acc:
            continue
        use = uses.setdefault(acc["bufferView"], {})
        size = COMPONENT_DTYPES[acc["componentType"]].itemsize * TYPE_SIZES[acc["type"]]
        if use.setdefault("element", size) != size:
            use["element"] = None
        if i in triangle_indices:
            use["triangles"] = True
        else:
            use["other"] = True
    for image in doc.get("images", []):
        if "bufferView" in image:
            uses.setdefault(image["bufferView"], {})["raw"] = True
    return uses


def _mode(view: dict, use: dict[str, Any] | None) -> tuple[str, int] | None:
    """("ATTRIBUTES" | "TRIANGLES", byte stride) for a view worth compressing, else None."""
    if not use or use.get("raw") or use.get("element") is None or view["byteLength"] < MIN_COMPRESSED_BYTES:
        return None
    if use.get("triangles") and not use.get("other"):
        size = use["element"]
        ok = size in (2, 4) and view["byteLength"] % (3 * size) == 0 and "byteStride" not in view
        return ("TRIANGLES", size) if ok else None
    stride = int(view.get("byteStride", use["element"]))
    if stride % 4 or stride > 256 or view["byteLength"] % stride:
        return None
    return "ATTRIBUTES", stride


def _encode(raw: bytes, mode: str, stride: int) -> bytes:
    import meshoptimizer

    if mode == "TRIANGLES":
        idx = np.frombuffer(raw, np.uint16 if stride == 2 else np.uint32)
        vertices = int(idx.max()) + 1 if len(idx) else 0
        return meshoptimizer.encode_index_buffer(idx, len(idx), vertices)
    meshoptimizer.encode_vertex_version(VERTEX_CODEC_VERSION)
    rows = np.frombuffer(raw, np.uint8).reshape(-1, stride)
    return meshoptimizer.encode_vertex_buffer(rows, len(rows), stride)


def compress_glb(doc: dict[str, Any], binary: bytes) -> bytes:
    """GLB bytes of ``doc`` (a glTF JSON whose views all lie in buffer 0 = ``binary``) with its vertex, morph,
    animation and triangle-index views compressed by EXT_meshopt_compression; other views stay raw."""
    doc = dict(doc)
    uses = _view_uses(doc)
    views, packed, fallback = [], [], 0
    offset = 0
    for i, view in enumerate(doc.get("bufferViews", [])):
        raw = binary[view.get("byteOffset", 0): view.get("byteOffset", 0) + view["byteLength"]]
        mode = _mode(view, uses.get(i))
        if mode is None:
            views.append({**view, "buffer": 0, "byteOffset": offset})
            data = raw
        else:
            data = _encode(raw, *mode)
            ext = {"buffer": 0, "byteOffset": offset, "byteLength": len(data), "byteStride": mode[1],
                   "mode": mode[0], "count": view["byteLength"] // mode[1]}
            views.append({**view, "buffer": 1, "byteOffset": fallback, "extensions": {EXT: ext}})
            fallback += _pad4(view["byteLength"])
        packed.append(data + b"\0" * (_pad4(len(data)) - len(data)))
        offset += _pad4(len(data))
    if not fallback:
        doc["bufferViews"] = views
        return pack_glb(doc, b"".join(packed))
    doc["bufferViews"] = views
    doc["buffers"] = [{"byteLength": offset},
                      {"byteLength": fallback, "extensions": {EXT: {"fallback": True}}}]
    for key in ("extensionsUsed", "extensionsRequired"):
        doc[key] = [*[e for e in doc.get(key, []) if e != EXT], EXT]
    return pack_glb(doc, b"".join(packed))


def decode_view(ext: dict[str, Any], buffers: list[bytes]) -> bytes:
    """The uncompressed bytes of a buffer view from its EXT_meshopt_compression object (filters applied)."""
    import meshoptimizer

    data = buffers[int(ext.get("buffer", 0))]
    start = int(ext.get("byteOffset", 0))
    src = data[start: start + int(ext["byteLength"])]
    count, stride, mode = int(ext["count"]), int(ext["byteStride"]), ext.get("mode")
    if mode == "ATTRIBUTES":
        out = meshoptimizer.decode_vertex_buffer(count, stride, src).view(np.uint8).reshape(-1)
        flt = ext.get("filter", "NONE")
        if flt != "NONE":
            decode = {"OCTAHEDRAL": meshoptimizer.decode_filter_oct,
                      "QUATERNION": meshoptimizer.decode_filter_quat,
                      "EXPONENTIAL": meshoptimizer.decode_filter_exp}[flt]
            out = np.asarray(decode(out.copy(), count, stride)).view(np.uint8).reshape(-1)
        return out[: count * stride].tobytes()
    if mode == "TRIANGLES":
        out = meshoptimizer.decode_index_buffer(count, stride, src)
    elif mode == "INDICES":
        out = meshoptimizer.decode_index_sequence(count, stride, src)
    else:
        raise ValueError(f"unknown EXT_meshopt_compression mode {mode!r}")
    return out.view(np.uint8)[: count * stride].tobytes()
