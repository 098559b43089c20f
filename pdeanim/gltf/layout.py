"""Where a clip's vertices go in an output glTF: a template document that keeps the source asset's look
(materials, textures, UVs, primitives, node names) with POSITION/NORMAL left to fill, and which range of the
clip's vertices each primitive takes. From a glTF/GLB source (vertex order of :func:`read_static_mesh`: scene
nodes depth-first, primitives in order), an OBJ (its UVs), or plain (one mesh of the clip's faces)."""

from __future__ import annotations

import copy
import io
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, MeshInputError, ParameterError
from .document import MESHOPT, GltfDocument, load_document, malformed_as
from .draco import DRACO, INDICES
from .glb import ARRAY_BUFFER, COMPONENT_DTYPES, COMPONENT_TYPES, ELEMENT_ARRAY_BUFFER, TYPE_SIZES
from .read import mesh_instances, read_static_mesh
from .scene import scene_order, world_matrices

log = logging.getLogger("pdeanim.gltf")
DROPPED_ATTRIBUTES = ("POSITION", "NORMAL", "TANGENT",  # recomputed (or, for tangents, left to the viewer)
                      "_PDEANIM_VERTEX")  # the map of a GLB pdeanim wrote, rewritten for each export
DROPPED_PREFIXES = ("JOINTS_", "WEIGHTS_")  # skinning is baked into the evaluated positions


@dataclass
class Slot:
    """One output primitive: ``doc["meshes"][mesh]["primitives"][prim]`` takes clip vertices start:stop."""

    mesh: int
    prim: int
    start: int
    stop: int
    normals: bool  # it has triangles and (a glTF source's primitive) had a NORMAL, so it gets one


@dataclass
class Part:
    """One mesh-holding node and the map from world (clip) coordinates to its local frame at rest."""

    node: int
    mesh: int
    to_local: np.ndarray  # (4, 4)
    slots: list[Slot]


@dataclass
class Layout:
    """Template glTF JSON (without buffers; ``views`` holds each bufferView's bytes) and where clip vertices
    go. ``faces`` (T, 3) over the clip's vertices and ``weld`` (V,) (vertices sharing a position and source
    normal get one smooth normal) drive the normals."""

    doc: dict[str, Any]
    views: list[bytes]
    parts: list[Part]
    n_vertices: int
    faces: np.ndarray
    weld: np.ndarray | None = None
    source: str = "plain"
    notes: list[str] = field(default_factory=list)

    @property
    def slots(self) -> list[Slot]:
        """Every output primitive in clip vertex order."""
        return [s for p in self.parts for s in p.slots]


def _asset(generator: str = "pdeanim") -> dict[str, Any]:
    return {"version": "2.0", "generator": generator}


def plain_layout(faces: np.ndarray | None, n_vertices: int, uv: np.ndarray | None = None) -> Layout:
    """One node, mesh and primitive holding every clip vertex; triangles when there are faces, else points;
    ``uv`` (V, 2) in glTF convention (origin top-left) becomes TEXCOORD_0."""
    f = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, np.int64).reshape(-1, 3)
    if len(f) and (f.min() < 0 or f.max() >= n_vertices):
        raise ParameterError(f"face indices must lie in [0, {n_vertices}), found {f.min()}..{f.max()}")
    views: list[bytes] = []
    doc: dict[str, Any] = {"asset": _asset(), "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
                           "bufferViews": [], "accessors": []}
    prim: dict[str, Any] = {"attributes": {}, "mode": 4 if len(f) else 0}
    if len(f):
        dtype = np.uint16 if n_vertices <= 65535 else np.uint32
        ordered = cache_order(f, n_vertices).reshape(-1).astype(dtype)
        prim["indices"] = add_accessor(doc, views, ordered, "SCALAR", ELEMENT_ARRAY_BUFFER)
    if uv is not None and len(uv) == n_vertices:
        uv32 = np.asarray(uv, np.float32)
        prim["attributes"]["TEXCOORD_0"] = add_accessor(doc, views, uv32, "VEC2", ARRAY_BUFFER)
    doc["meshes"] = [{"primitives": [prim]}]
    slot = Slot(0, 0, 0, int(n_vertices), bool(len(f)))
    return Layout(doc, views, [Part(0, 0, np.eye(4), [slot])], int(n_vertices), f, None,
                  "obj" if "TEXCOORD_0" in prim["attributes"] else "plain")


def cache_order(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """The triangles reordered for the GPU's vertex cache (meshoptimizer), which also makes the index stream
    compress about 2x better; each triangle and the vertex order stay as they were."""
    import meshoptimizer

    src = np.ascontiguousarray(faces.reshape(-1), np.uint32)
    out = np.zeros_like(src)
    meshoptimizer.optimize_vertex_cache(out, src, len(src), int(n_vertices))
    return out.reshape(-1, 3).astype(np.int64)


def add_view(doc: dict, views: list[bytes], raw: bytes, target: int | None = None,
             stride: int | None = None) -> int:
    """Append a buffer view (its offset is set when the GLB is assembled); returns its index."""
    view: dict[str, Any] = {"buffer": 0, "byteLength": len(raw)}
    if stride is not None:
        view["byteStride"] = stride
    if target is not None:
        view["target"] = target
    doc.setdefault("bufferViews", []).append(view)
    views.append(bytes(raw))
    return len(doc["bufferViews"]) - 1


def add_accessor(doc: dict, views: list[bytes], data: np.ndarray, acc_type: str, target: int | None = None,
                 *, normalized: bool = False, minmax: bool = False, view: int | None = None,
                 byte_offset: int = 0) -> int:
    """Append an accessor over ``data`` (N, k) (its own tightly packed view unless ``view`` is given)."""
    a = np.asarray(data)
    flat = a.reshape(len(a), -1)
    if view is None:
        view = add_view(doc, views, np.ascontiguousarray(flat, a.dtype.newbyteorder("<")).tobytes(), target)
    acc: dict[str, Any] = {"bufferView": view, "componentType": COMPONENT_TYPES[np.dtype(a.dtype)],
                           "count": int(len(a)), "type": acc_type}
    if byte_offset:
        acc["byteOffset"] = int(byte_offset)
    if normalized:
        acc["normalized"] = True
    if minmax:
        acc.update(minmax_of(flat))
    doc.setdefault("accessors", []).append(acc)
    return len(doc["accessors"]) - 1


def minmax_of(flat: np.ndarray) -> dict[str, list]:
    """Exact ``min``/``max`` of (N, k) data as JSON lists (float32 values or integers); one strided reduction
    per component (numpy reduces over rows of a few values about 20x slower)."""
    lo = [flat[:, c].min() for c in range(flat.shape[1])]
    hi = [flat[:, c].max() for c in range(flat.shape[1])]
    if np.issubdtype(flat.dtype, np.floating):
        return {"min": [float(np.float32(x)) for x in lo], "max": [float(np.float32(x)) for x in hi]}
    return {"min": [int(x) for x in lo], "max": [int(x) for x in hi]}


def accessor_rows(doc: dict, views: list[bytes], index: int) -> np.ndarray:
    """The values of accessor ``index`` of a template (views' bytes in ``views``) as (count, components)
    of its own component type, strides and sparse substitutions applied: the bytes a writer copies."""
    acc = doc["accessors"][index]
    dtype = COMPONENT_DTYPES[acc["componentType"]]
    count, width = int(acc["count"]), TYPE_SIZES[acc["type"]]
    out = np.zeros((count, width), dtype)
    if "bufferView" in acc and count:
        raw = views[acc["bufferView"]]
        elem = width * dtype.itemsize
        stride = int(doc["bufferViews"][acc["bufferView"]].get("byteStride", elem))
        start = int(acc.get("byteOffset", 0))
        span = np.frombuffer(raw, np.uint8, (count - 1) * stride + elem, start)
        rows = np.lib.stride_tricks.as_strided(span, (count, elem), (stride, 1))
        out = np.ascontiguousarray(rows).view(dtype).reshape(count, width)
    sparse = acc.get("sparse")
    if sparse:
        n = int(sparse["count"])
        ind, val = sparse["indices"], sparse["values"]
        idx = np.frombuffer(views[ind["bufferView"]], COMPONENT_DTYPES[ind["componentType"]], n,
                            int(ind.get("byteOffset", 0)))
        out = out.copy()
        out[idx.astype(np.int64)] = np.frombuffer(views[val["bufferView"]], dtype, n * width,
                                                  int(val.get("byteOffset", 0))).reshape(n, width)
    return out


def drop_unused(doc: dict, views: list[bytes]) -> list[bytes]:
    """Remove the accessors and buffer views nothing refers to any more (meshes, animations, skins, images),
    renumbering the rest in place; returns the kept views' bytes."""
    refs: set[int] = set()
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            refs.update(prim.get("attributes", {}).values())
            refs.update(v for t in prim.get("targets", []) for v in t.values())
            if "indices" in prim:
                refs.add(prim["indices"])
    for anim in doc.get("animations", []):
        refs.update(i for s in anim.get("samplers", []) for i in (s["input"], s["output"]))
    refs.update(s["inverseBindMatrices"] for s in doc.get("skins", []) if "inverseBindMatrices" in s)
    acc_keep = sorted(refs)
    acc_map = {old: new for new, old in enumerate(acc_keep)}
    accessors = [doc["accessors"][i] for i in acc_keep]
    used = {a["bufferView"] for a in accessors if "bufferView" in a}
    used |= {a["sparse"][p]["bufferView"] for a in accessors if "sparse" in a for p in ("indices", "values")}
    used |= {im["bufferView"] for im in doc.get("images", []) if "bufferView" in im}
    view_keep = sorted(used)
    view_map = {old: new for new, old in enumerate(view_keep)}
    for acc in accessors:
        if "bufferView" in acc:
            acc["bufferView"] = view_map[acc["bufferView"]]
        for part in ("indices", "values") if "sparse" in acc else ():
            acc["sparse"][part]["bufferView"] = view_map[acc["sparse"][part]["bufferView"]]
    for image in doc.get("images", []):
        if "bufferView" in image:
            image["bufferView"] = view_map[image["bufferView"]]
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            prim["attributes"] = {k: acc_map[v] for k, v in prim.get("attributes", {}).items()}
            if "targets" in prim:
                prim["targets"] = [{k: acc_map[v] for k, v in t.items()} for t in prim["targets"]]
            if "indices" in prim:
                prim["indices"] = acc_map[prim["indices"]]
    for anim in doc.get("animations", []):
        for s in anim.get("samplers", []):
            s["input"], s["output"] = acc_map[s["input"]], acc_map[s["output"]]
    for skin in doc.get("skins", []):
        if "inverseBindMatrices" in skin:
            skin["inverseBindMatrices"] = acc_map[skin["inverseBindMatrices"]]
    doc["accessors"] = accessors
    doc["bufferViews"] = [doc["bufferViews"][i] for i in view_keep]
    return [views[i] for i in view_keep]


def _strip_primitive(prim: dict) -> dict:
    out = copy.deepcopy(prim)
    attrs = {k: v for k, v in out.get("attributes", {}).items()
             if k not in DROPPED_ATTRIBUTES and not k.startswith(DROPPED_PREFIXES)}
    out["attributes"] = attrs
    out.pop("targets", None)
    if isinstance(out.get("extensions"), dict):  # its Draco stream is written out plain
        out["extensions"].pop(DRACO, None)
        if not out["extensions"]:
            del out["extensions"]
    return out


def _collect(doc: dict) -> tuple[list[int], list[int]]:
    """Accessors and buffer views the document still refers to (meshes and images), each sorted."""
    accessors: set[int] = set()
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            accessors.update(prim.get("attributes", {}).values())
            if "indices" in prim:
                accessors.add(prim["indices"])
            for target in prim.get("targets", []):
                accessors.update(target.values())
    views = set()
    for i in accessors:
        acc = doc["accessors"][i]
        if "bufferView" in acc:
            views.add(acc["bufferView"])
        for part in ("indices", "values"):
            if "sparse" in acc:
                views.add(acc["sparse"][part]["bufferView"])
    for image in doc.get("images", []):
        if "bufferView" in image:
            views.add(image["bufferView"])
    return sorted(accessors), sorted(views)


def _compact(doc: dict, gd: GltfDocument) -> list[bytes]:
    """Keep only referenced meshes, accessors and views (renumbered); returns the kept views' bytes."""
    used_meshes = sorted({n["mesh"] for n in doc.get("nodes", []) if "mesh" in n})
    mesh_map = {old: new for new, old in enumerate(used_meshes)}
    doc["meshes"] = [doc["meshes"][i] for i in used_meshes]
    for node in doc.get("nodes", []):
        if "mesh" in node:
            node["mesh"] = mesh_map[node["mesh"]]
    doc["accessors"] = copy.deepcopy(gd.list("accessors"))
    acc_keep, view_keep = _collect(doc)
    acc_map = {old: new for new, old in enumerate(acc_keep)}
    view_map = {old: new for new, old in enumerate(view_keep)}
    for mesh in doc["meshes"]:
        for prim in mesh.get("primitives", []):
            prim["attributes"] = {k: acc_map[v] for k, v in prim.get("attributes", {}).items()}
            if "indices" in prim:
                prim["indices"] = acc_map[prim["indices"]]
    accessors = [doc["accessors"][i] for i in acc_keep]
    for acc in accessors:
        if "bufferView" in acc:
            acc["bufferView"] = view_map[acc["bufferView"]]
        for part in ("indices", "values"):
            if "sparse" in acc:
                acc["sparse"][part]["bufferView"] = view_map[acc["sparse"][part]["bufferView"]]
    doc["accessors"] = accessors
    for image in doc.get("images", []):
        if "bufferView" in image:
            image["bufferView"] = view_map[image["bufferView"]]
    views, data = [], []
    for i in view_keep:
        view = {k: v for k, v in gd.item("bufferViews", i).items() if k not in ("byteOffset", "extensions")}
        view["buffer"] = 0
        views.append(view)
        data.append(gd.view_bytes(i))
    doc["bufferViews"] = views
    for new, old in enumerate(acc_keep):  # Draco-compressed accessors get plain views of their values
        if old in gd.draco:
            acc = accessors[new]
            acc.pop("byteOffset", None)
            target = ELEMENT_ARRAY_BUFFER if gd.draco[old][1] == INDICES else ARRAY_BUFFER
            acc["bufferView"] = add_view(doc, data, gd.draco_values(old).tobytes(), target)
    return data


def _weld(verts: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(V,) ids shared by vertices at the same rest position with the same source normal (UV seams), so
    seams stay smooth while hard edges (split normals) stay hard."""
    key = np.concatenate([verts, np.rint(normals * 1000.0)], axis=1)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    return inverse.reshape(-1).astype(np.int64)


def gltf_layout(source: str | Path | bytes) -> Layout:
    """The template of a glTF/GLB source: its document without animations and skins, each mesh node's mesh
    copied with POSITION, NORMAL, TANGENT, skin attributes and morph targets removed."""
    gd = load_document(source, MeshInputError)
    with malformed_as(MeshInputError):
        verts, faces = read_static_mesh(source)
        instances = mesh_instances(gd)
        world = world_matrices(gd, {}, np.zeros(1))[0]
        doc = {k: copy.deepcopy(v) for k, v in gd.doc.items()
               if k not in ("animations", "skins", "buffers", "bufferViews", "accessors")}
        doc["asset"] = {**doc.get("asset", {}), "generator": "pdeanim (from " +
                        str(gd.doc.get("asset", {}).get("generator", "a glTF asset"))[:80] + ")"}
        nodes = doc.get("nodes", [])
        for node in nodes:
            node.pop("skin", None)
            node.pop("weights", None)
        meshes = doc.setdefault("meshes", [])
        parts: list[Part] = []
        src_normals = np.zeros_like(verts)
        start = 0
        order = [n for n in scene_order(gd) if "mesh" in gd.list("nodes")[n]]
        by_node: dict[int, list] = {}
        for inst in instances:
            by_node.setdefault(inst.node, []).append(inst)
        for n in order:
            src_mesh = gd.item("meshes", nodes[n]["mesh"])
            new = {k: copy.deepcopy(v) for k, v in src_mesh.items() if k != "weights"}
            if isinstance(new.get("extras"), dict):
                new["extras"].pop("targetNames", None)
            new["primitives"] = [_strip_primitive(p) for p in src_mesh.get("primitives", [])]
            meshes.append(new)
            nodes[n]["mesh"] = len(meshes) - 1
            m = world[n]
            if abs(np.linalg.det(m[:3, :3])) < 1e-30:
                raise MeshInputError(f"node {n} has a singular transform; its positions cannot be made local")
            slots = []
            for j, (inst, prim) in enumerate(zip(by_node[n], src_mesh.get("primitives", []), strict=True)):
                count = len(inst.primitive.positions)
                if "NORMAL" in prim.get("attributes", {}):
                    nrm = gd.accessor(prim["attributes"]["NORMAL"])
                    if nrm.shape == (count, 3):
                        src_normals[start: start + count] = nrm
                smooth = "NORMAL" in prim.get("attributes", {})  # without NORMAL, viewers shade it flat
                slots.append(Slot(len(meshes) - 1, j, start, start + count,
                                  smooth and bool(len(inst.primitive.faces))))
                start += count
            parts.append(Part(n, len(meshes) - 1, np.linalg.inv(m), slots))
        views = _compact(doc, gd)
        for part in parts:  # meshes were renumbered
            part.mesh = doc["nodes"][part.node]["mesh"]
            for slot in part.slots:
                slot.mesh = part.mesh
        for key in ("extensionsUsed", "extensionsRequired"):
            if key in doc:
                doc[key] = [e for e in doc[key] if e not in (MESHOPT, DRACO)]
                if not doc[key]:
                    del doc[key]
    return Layout(doc, views, parts, int(start), faces.astype(np.int64), _weld(verts, src_normals), "gltf")


def obj_uv(data: bytes) -> np.ndarray | None:
    """Per-vertex UVs of an OBJ in file vertex order (glTF convention, v flipped), or None when trimesh gives
    none (no ``vt``, or a vertex with several UVs)."""
    import trimesh

    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type="obj", process=False, maintain_order=True)
    except Exception:  # noqa: BLE001 - the mesh itself was validated on upload; UVs are optional
        return None
    finally:
        logger.setLevel(level)
    uv = getattr(getattr(loaded, "visual", None), "uv", None)
    if uv is None or len(uv) != len(getattr(loaded, "vertices", [])):
        return None
    uv = np.asarray(uv, np.float64)
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)


def source_layout(data: bytes | None, filename: str, faces: np.ndarray | None, n_vertices: int) -> Layout:
    """The layout that keeps what the source mesh file had (glTF look, OBJ UVs), or the plain one when the
    file is absent, of another kind, or does not match the clip's vertex count (the reason goes to notes)."""
    suffix = Path(filename).suffix.lower()
    plain = plain_layout(faces, n_vertices)
    if data is None:
        return plain
    try:
        if suffix in (".glb", ".gltf"):
            layout = gltf_layout(data)
        elif suffix == ".obj":
            uv = obj_uv(data)
            if uv is None:
                return plain
            layout = plain_layout(faces, n_vertices, uv) if len(uv) == n_vertices else Layout(
                plain.doc, plain.views, plain.parts, len(uv), plain.faces)
        else:
            return plain
    except InputError as exc:
        plain.notes.append(f"source mesh not used: {exc}")
        return plain
    if layout.n_vertices != n_vertices:
        plain.notes.append(f"source mesh has {layout.n_vertices} vertices, the clip {n_vertices}: "
                           "written plain")
        log.info("%s", plain.notes[-1])
        return plain
    return layout
