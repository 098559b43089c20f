"""Draco-compress the mesh primitives of a GLB made in a test (DracoPy's encoder), as exporters do: each
primitive's indices and vertex attributes move into one KHR_draco_mesh_compression stream (vertex order
kept), their accessors lose their buffer views, and the extension becomes required."""

from __future__ import annotations

import numpy as np

from pdeanim.gltf.document import load_document
from pdeanim.gltf.draco import DRACO
from pdeanim.gltf.glb import COMPONENT_DTYPES, pack_glb, unpack_glb


def _pad(raw: bytes) -> bytes:
    return raw + b"\0" * (-len(raw) % 4)


def draco_glb(glb: bytes, quantization_bits: int = 16) -> bytes:
    """``glb`` with every mesh primitive Draco-compressed (POSITION quantised to ``quantization_bits``,
    TEXCOORD_0 as floats, the other attributes as generic attributes in their own component type)."""
    import DracoPy

    gd = load_document(glb)
    doc, binary = unpack_glb(glb)
    binary = binary or b""
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            attrs = prim["attributes"]
            pos = gd.accessor(attrs["POSITION"])
            faces = gd.accessor(prim["indices"]).reshape(-1, 3).astype(np.uint32)
            generic, order = {}, []
            uv = gd.accessor(attrs["TEXCOORD_0"]) if "TEXCOORD_0" in attrs else None
            for k, (name, acc) in enumerate(sorted(attrs.items())):
                if name in ("POSITION", "TEXCOORD_0"):
                    continue
                spec = doc["accessors"][acc]
                raw = gd._strided(spec["bufferView"], spec.get("byteOffset", 0), spec["count"],
                                  gd.accessor(acc).shape[1], COMPONENT_DTYPES[spec["componentType"]])
                generic[10 + k] = raw if raw.dtype != np.float32 else raw.astype(np.float32)
                order.append((name, 10 + k))
            stream = DracoPy.encode(pos, faces, quantization_bits=quantization_bits, preserve_order=True,
                                    tex_coord=uv, generic_attributes=generic or None)
            decoded = DracoPy.decode(stream)
            ids = {a["attribute_type"]: a["unique_id"] for a in decoded.attributes}
            ext_attrs = {"POSITION": ids[0], **dict(order)}
            if uv is not None:
                ext_attrs["TEXCOORD_0"] = ids[3]
            doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(binary),
                                                      "byteLength": len(stream)})
            binary = _pad(binary + stream)
            prim.setdefault("extensions", {})[DRACO] = {"bufferView": len(doc["bufferViews"]) - 1,
                                                        "attributes": ext_attrs}
            for acc in [prim["indices"], *(attrs[name] for name in ext_attrs)]:
                doc["accessors"][acc].pop("bufferView", None)
                doc["accessors"][acc].pop("byteOffset", None)
    doc["buffers"][0]["byteLength"] = len(binary)
    for key in ("extensionsUsed", "extensionsRequired"):
        doc[key] = sorted({*doc.get(key, []), DRACO})
    return pack_glb(doc, binary)
