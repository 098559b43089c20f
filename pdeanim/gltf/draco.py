"""KHR_draco_mesh_compression input (PyPI ``DracoPy``, a wrapper of Google's Draco decoder): which accessors
a Draco stream holds (a compressed primitive's indices and the attributes its extension lists, each by its
Draco unique id) and their values from the decoded stream, checked against the counts and types the
accessors declare (what the declared-size limits were checked on)."""

from __future__ import annotations

from typing import Any

import numpy as np

DRACO = "KHR_draco_mesh_compression"
INDICES = -1
"""The Draco "attribute" of a primitive's indices (its faces)."""


def draco_accessors(doc: dict[str, Any]) -> dict[int, tuple[int, int]]:
    """Accessor index -> (bufferView of the Draco stream, Draco unique id or INDICES) for every primitive
    compressed with Draco; malformed entries are left out (decoding them fails on their missing data)."""
    out: dict[int, tuple[int, int]] = {}
    meshes = doc.get("meshes")
    for mesh in meshes if isinstance(meshes, list) else []:
        prims = mesh.get("primitives") if isinstance(mesh, dict) else None
        for prim in prims if isinstance(prims, list) else []:
            ext = ((prim.get("extensions") or {}) if isinstance(prim, dict) else {}).get(DRACO)
            if not isinstance(ext, dict) or not isinstance(ext.get("bufferView"), int):
                continue
            view, attrs = ext["bufferView"], prim.get("attributes") or {}
            if isinstance(prim.get("indices"), int):
                out[prim["indices"]] = (view, INDICES)
            for name, uid in (ext.get("attributes") or {}).items():
                if isinstance(attrs, dict) and isinstance(attrs.get(name), int) and isinstance(uid, int):
                    out[attrs[name]] = (view, uid)
    return out


def decode_stream(data: bytes) -> Any:
    """The decoded Draco mesh of one stream; ValueError when it is no Draco mesh."""
    import DracoPy

    try:
        mesh = DracoPy.decode(bytes(data))
    except Exception as exc:  # noqa: BLE001 - DracoPy raises its own and RuntimeError types on bad data
        raise ValueError(f"Draco decoding failed: {exc}") from exc
    if not hasattr(mesh, "faces"):
        raise ValueError("the Draco stream holds a point cloud, not a mesh")
    return mesh


def stream_values(mesh: Any, uid: int, count: int, width: int) -> np.ndarray:
    """(count, width) values of attribute ``uid`` (or the indices) of a decoded Draco mesh; ValueError when
    the stream lacks it or its size differs from what the accessor declares."""
    if uid == INDICES:
        data = np.asarray(mesh.faces).reshape(-1, 1)
    else:
        attr = mesh.get_attribute_by_unique_id(uid)
        if attr is None:
            raise ValueError(f"the Draco stream has no attribute with unique id {uid}")
        data = np.asarray(attr["data"])
        data = data.reshape(len(data), -1)
    if data.shape != (count, width):
        what = "indices" if uid == INDICES else f"attribute {uid}"
        raise ValueError(f"Draco {what} decode to {data.shape[0]} x {data.shape[1]} values, the accessor "
                         f"declares {count} x {width}")
    return data
