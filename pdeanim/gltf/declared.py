"""What a glTF document declares it will take to read, checked from its JSON alone before any scene walk or
decoding: node, accessor and primitive counts, counts past 2^31, the vertices the scene's primitives declare,
and the bytes its EXT_meshopt_compression views and KHR_draco_mesh_compression streams decode to (each
meshopt view no more than its accessors read, each Draco stream what its accessors declare, all of them
within the decode budget). A small file that declares a lot is refused in milliseconds with the figures,
instead of after seconds of work and gigabytes of memory."""

from __future__ import annotations

from typing import Any

from ..errors import LimitError
from .document import MAX_COUNT, MESHOPT, GltfDocument, meshopt_size
from .glb import COMPONENT_DTYPES, TYPE_SIZES
from .scene import scene_order


def check_declared(gd: GltfDocument, max_vertices: int | None = None) -> None:
    """Refuse ``gd`` (LimitError, or its InputError class) when what it declares is over its limits or
    ``max_vertices``, before anything is decoded."""
    limits = gd.limits
    for key, limit, setting in (("nodes", limits.max_nodes, "PDEANIM_MAX_GLTF_NODES"),
                                ("accessors", limits.max_accessors, "PDEANIM_MAX_GLTF_ACCESSORS")):
        if len(gd.list(key)) > limit:
            raise LimitError(f"glTF {key} count", len(gd.list(key)), limit, setting)
    counts = [_count(gd, i, acc) for i, acc in enumerate(gd.list("accessors"))]
    compressed = _compressed_bytes(gd)
    draco = sum(counts[a] * _width(gd.list("accessors")[a]) * 4 for a in gd.draco if 0 <= a < len(counts))
    outputs = sum(c * _width(acc) * 8 for c, acc in zip(counts, gd.list("accessors"), strict=True))
    if compressed + draco + outputs > limits.max_decoded_bytes:
        raise LimitError(f"decoded size the glTF declares in bytes ({compressed} in EXT_meshopt_compression "
                         f"views, {draco} in KHR_draco_mesh_compression streams, {outputs} in accessors)",
                         compressed + draco + outputs, limits.max_decoded_bytes, "PDEANIM_MAX_DECODED_BYTES")
    nodes = gd.list("nodes")
    primitives = [prim for n in scene_order(gd) if "mesh" in nodes[n]
                  for prim in gd.item("meshes", nodes[n]["mesh"]).get("primitives", [])]
    if len(primitives) > limits.max_primitives:
        raise LimitError("glTF mesh primitives in the scene", len(primitives), limits.max_primitives,
                         "PDEANIM_MAX_GLTF_PRIMITIVES")
    position = [(prim.get("attributes") or {}).get("POSITION") for prim in primitives]
    declared = sum(counts[p] for p in position if isinstance(p, int) and 0 <= p < len(counts))
    if max_vertices is not None and declared > max_vertices:
        raise LimitError("vertex count the glTF scene declares", declared, max_vertices,
                         "PDEANIM_MAX_VERTICES")


def _count(gd: GltfDocument, index: int, acc: Any) -> int:
    """The count accessor ``index`` declares, refused when it is not an integer in [0, 2^31)."""
    count = acc.get("count") if isinstance(acc, dict) else None
    if not isinstance(count, int) or isinstance(count, bool) or not 0 <= count <= MAX_COUNT:
        raise gd.error(f"accessor {index} declares count {count!r}, not an integer in [0, {MAX_COUNT}]")
    return count


def _width(acc: dict) -> int:
    """Components per element of an accessor (1 when its type is unknown: decoding will refuse it)."""
    return TYPE_SIZES.get(acc.get("type"), 1)


def _reads(gd: GltfDocument) -> dict[int, int]:
    """For each buffer view, the end of the last byte an accessor (or a sparse part of one) reads of it."""
    views = gd.list("bufferViews")
    ends: dict[int, int] = {}

    def read(view: Any, offset: Any, count: int, elem: int) -> None:
        if not (isinstance(view, int) and 0 <= view < len(views) and isinstance(offset, int) and count):
            return
        stride = views[view].get("byteStride", elem) if isinstance(views[view], dict) else elem
        stride = stride if isinstance(stride, int) else elem
        ends[view] = max(ends.get(view, 0), offset + (count - 1) * stride + elem)

    for acc in gd.list("accessors"):
        if not isinstance(acc, dict):
            continue
        dtype = COMPONENT_DTYPES.get(acc.get("componentType"))
        size = dtype.itemsize if dtype is not None else 4
        count = acc.get("count") if isinstance(acc.get("count"), int) else 0
        read(acc.get("bufferView"), acc.get("byteOffset", 0), count, _width(acc) * size)
        sparse = acc.get("sparse")
        if isinstance(sparse, dict) and isinstance(sparse.get("count"), int):
            ind, val = sparse.get("indices") or {}, sparse.get("values") or {}
            ind_type = COMPONENT_DTYPES.get(ind.get("componentType")) if isinstance(ind, dict) else None
            if isinstance(ind, dict) and ind_type is not None:
                read(ind.get("bufferView"), ind.get("byteOffset", 0), sparse["count"], ind_type.itemsize)
            if isinstance(val, dict):
                read(val.get("bufferView"), val.get("byteOffset", 0), sparse["count"], _width(acc) * size)
    return ends


def _compressed_bytes(gd: GltfDocument) -> int:
    """Total bytes the EXT_meshopt_compression views declare they decode to; a view that decodes to more
    than its accessors read (plus one element) is refused: its only effect would be the allocation."""
    reads, total = _reads(gd), 0
    for i, view in enumerate(gd.list("bufferViews")):
        ext = (view.get("extensions") or {}).get(MESHOPT) if isinstance(view, dict) else None
        if not isinstance(ext, dict):
            continue
        size = meshopt_size(ext, i, gd.error)
        stride = size // max(int(ext.get("count", 1)), 1)
        if i in reads and size > reads[i] + stride:
            raise gd.error(f"compressed bufferView {i} declares {size} decoded bytes but its accessors read "
                           f"{reads[i]} of them: refused before decoding (a decompression bomb)")
        total += size
    return total
