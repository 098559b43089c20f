"""The audit's hostile upload corpus, generated in the test (never committed): meshopt decompression bombs
(one view, several views sharing one stream), deep JSON, node and primitive floods, declared counts past 2^31,
and .npz bombs. Each is small on the wire and declares far more work or memory than it holds."""

from __future__ import annotations

import io
import json
import struct
import zipfile

import numpy as np

from pdeanim.gltf.glb import pack_glb

TETRA = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
TETRA_FACES = np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.uint16)
MESHOPT = "EXT_meshopt_compression"
STRIDE = 16  # bytes per element of the zero streams below (VEC3 float positions with a stride of 16)


def zero_stream(decoded: int) -> bytes:
    """A valid EXT_meshopt_compression ATTRIBUTES stream (stride 16) that decodes to ``decoded`` zero bytes
    (a multiple of 4 KiB): the vertex codec stores 256 zero vertices in a 64-byte block of zeros, so the
    stream is 1/64 of what it decodes to: header byte 0xA0, the blocks, a 32-byte tail (the first vertex)."""
    assert decoded % (256 * STRIDE) == 0
    return b"\xa0" + bytes(decoded // 64) + bytes(32)


def _tetra_doc(positions_view: int | None = None, count: int = 4) -> tuple[dict, bytes]:
    """A one-node tetrahedron document; POSITION on a plain view, or on view ``positions_view``."""
    raw = TETRA.tobytes() + TETRA_FACES.tobytes()
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
             {"buffer": 0, "byteOffset": 48, "byteLength": 24}]
    position = {"bufferView": 0 if positions_view is None else positions_view, "componentType": 5126,
                "count": count, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]}
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "accessors": [position, {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}],
           "bufferViews": views, "buffers": [{"byteLength": len(raw)}]}
    return doc, raw


def meshopt_bomb(decoded: int, views: int = 1) -> bytes:
    """A tetrahedron whose POSITION (and morph targets, one per extra view) read 4 vertices from
    EXT_meshopt_compression views that each decode to ``decoded`` bytes, all sharing one stream."""
    doc, raw = _tetra_doc()
    stream = zero_stream(decoded)
    start = len(raw) + (-len(raw)) % 4
    ext = {"buffer": 0, "byteOffset": start, "byteLength": len(stream), "byteStride": STRIDE,
           "count": decoded // STRIDE, "mode": "ATTRIBUTES"}
    first = len(doc["bufferViews"])
    for _ in range(views):
        doc["bufferViews"].append({"buffer": 1, "byteOffset": 0, "byteLength": decoded, "byteStride": STRIDE,
                                   "extensions": {MESHOPT: ext}})
    targets = []
    for k in range(views):
        doc["accessors"].append({"bufferView": first + k, "componentType": 5126, "count": 4, "type": "VEC3"})
        targets.append(len(doc["accessors"]) - 1)
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"]["POSITION"] = targets[0]
    if views > 1:
        prim["targets"] = [{"POSITION": t} for t in targets[1:]]
    doc["buffers"] = [{"byteLength": start + len(stream)},
                      {"byteLength": decoded, "extensions": {MESHOPT: {"fallback": True}}}]
    doc["extensionsUsed"] = doc["extensionsRequired"] = [MESHOPT]
    return pack_glb(doc, raw + bytes(start - len(raw)) + stream)


def meshopt_count_bomb(count: int) -> bytes:
    """A tetrahedron plus a compressed view whose extension declares ``count`` elements (past 2^31)."""
    doc, raw = _tetra_doc()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": 0, "byteLength": 48, "byteStride": 4,
                               "extensions": {MESHOPT: {"buffer": 0, "byteOffset": 0, "byteLength": 48,
                                                        "byteStride": 4, "count": count,
                                                        "mode": "ATTRIBUTES"}}})
    doc["accessors"].append({"bufferView": 2, "componentType": 5126, "count": 4, "type": "SCALAR"})
    doc["meshes"][0]["primitives"][0]["attributes"]["_WEIGHT"] = 2
    doc["extensionsUsed"] = doc["extensionsRequired"] = [MESHOPT]
    return pack_glb(doc, raw)


def accessor_count_bomb(count: int) -> bytes:
    """A tetrahedron plus an accessor, used by nothing, that declares ``count`` values (past 2^31)."""
    doc, raw = _tetra_doc()
    doc["accessors"].append({"componentType": 5126, "count": count, "type": "SCALAR"})
    return pack_glb(doc, raw)


def deep_json(depth: int) -> bytes:
    """A GLB whose JSON nests ``depth`` arrays in its extras (deeper than Python's json module can load)."""
    doc, raw = _tetra_doc()
    doc["extras"] = "@@"
    return _glb_text(json.dumps(doc).replace('"@@"', "[" * depth + "]" * depth), raw)


def _glb_text(text: str, raw: bytes) -> bytes:
    """GLB bytes around JSON given as text (for JSON Python itself cannot load)."""
    js = text.encode() + b" " * ((-len(text.encode())) % 4)
    binary = raw + bytes((-len(raw)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def node_flood(nodes: int) -> bytes:
    """A tetrahedron mesh placed by ``nodes`` root nodes."""
    doc, raw = _tetra_doc()
    doc["nodes"] = [{"mesh": 0}] * nodes
    doc["scenes"] = [{"nodes": list(range(nodes))}]
    return pack_glb(doc, raw)


def primitive_flood(primitives: int, vertices: int = 4) -> bytes:
    """One node whose mesh has ``primitives`` copies of a tetrahedron primitive with ``vertices`` vertices
    (the tetrahedron's 4, then unreferenced zeros)."""
    doc, raw = _tetra_doc()
    if vertices > 4:
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(raw), "byteLength": 12 * vertices})
        doc["accessors"][0].update(bufferView=2, count=vertices)
        raw = raw + TETRA.tobytes() + bytes(12 * (vertices - 4))
        doc["buffers"] = [{"byteLength": len(raw)}]
    doc["meshes"][0]["primitives"] = doc["meshes"][0]["primitives"] * primitives
    return pack_glb(doc, raw)


def npz_zeros(frames: int, vertices: int) -> bytes:
    """A POSES.npz of ``frames`` x ``vertices`` zero positions, deflated (about 1/1000 of its size),
    written in chunks so the test never holds the inflated array."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f4", "fortran_order": False, "shape": (frames, vertices, 3)})
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf, \
            zf.open("vertices.npy", "w", force_zip64=True) as member:
        member.write(header.getvalue())
        frame = bytes(vertices * 12)
        for _ in range(frames):
            member.write(frame)
    return out.getvalue()
