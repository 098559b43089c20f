"""GLB of evaluated positions in a :class:`~.layout.Layout` (so a glTF source keeps its look): one frame
(float32 positions and unit normals), or an animation as morph targets with a one-hot ``weights`` track,
small by default: positions on an integer grid (KHR_mesh_quantization), triangles in vertex-cache order,
normals and their per-frame deltas as normalized bytes, and every stream compressed with
EXT_meshopt_compression. The grid's step is either ``position_bits`` per axis over the animation's extent
(14 gives 6.1e-5 of it) or, given ``position_error``, the coarsest step whose rounding adds at most that RMS
distance to the frames (a clip export passes a share of the clip's own fit error: no finer than the clip
needs, see :mod:`.clipexport`).

Each mesh node's positions are quantised in its own local frame; the dequantising translation and uniform
scale go on the node itself when it is a plain leaf (the plain layout), else on a new child node that holds
the mesh, so the source's node transforms, names and children are untouched.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError
from .glb import ARRAY_BUFFER, pack_glb
from .layout import Layout, Part, Slot, add_accessor, add_view, drop_unused, minmax_of
from .meshopt import compress_glb
from .normals import unit_normals_frames
from .weld import flat_shaded, map_all_or_none, smooth_groups, weld_primitive

QUANT = "KHR_mesh_quantization"
TARGET_VIEW_VALUES = 48_000_000  # morph-target bytes per buffer view (one meshopt stream) at most


@dataclass(frozen=True)
class PackOptions:
    """How an animation GLB is stored: ``quantize`` positions to ``position_bits`` (8..15, default 14) per
    axis over the frames' extent (max error half a step) or, with ``position_bits=None``, to the coarsest
    step whose rounding adds an RMS distance of at most ``position_error`` (world units; uniform rounding to
    a step s is s/2 RMS over three axes) while keeping 8..15 bits of the extent (14 bits when
    ``position_error`` is None too), and normals to bytes, ``compress`` with EXT_meshopt_compression,
    ``normals`` as per-frame morph deltas (else every frame is lit with the first frame's normals), ``weld``
    vertices whose written data are all equal (see :mod:`.weld`; off keeps one vertex per clip vertex, in
    clip order). A welded primitive's vertices come in
    the triangles' fetch order with a ``_PDEANIM_VERTEX`` map to the clip's, also where nothing merged (the
    order alone takes a mesh in capture order to 0.62x, see docs/gltf.md)."""

    quantize: bool = True
    compress: bool = True
    position_bits: int | None = 14
    normals: bool = True
    weld: bool = True
    position_error: float | None = None

    def __post_init__(self) -> None:
        if self.position_bits is not None and not 8 <= int(self.position_bits) <= 15:
            raise ParameterError(f"position_bits must lie in [8, 15], got {self.position_bits}")
        err = self.position_error
        if err is not None and not (isinstance(err, (int, float)) and np.isfinite(err) and err > 0):
            raise ParameterError(f"position_error must be a positive number, got {err!r}")

    def grid_step(self, part_stretch: float = 1.0) -> float | None:
        """The grid step asked for in a part's local units (None: ``position_bits`` decide), where
        ``part_stretch`` is the most its local-to-world map lengthens a vector."""
        if self.position_bits is not None or self.position_error is None:
            return None
        return 2.0 * float(self.position_error) / max(part_stretch, 1e-300)


def _check_frames(frames: np.ndarray, layout: Layout) -> np.ndarray:
    """Frames (K, V, 3) as float32 (no copy when they are already): the clip's evaluation precision."""
    f = np.asarray(frames)
    if f.ndim != 3 or f.shape[1:] != (layout.n_vertices, 3):
        raise ParameterError(f"frames must have shape (K, {layout.n_vertices}, 3), got {f.shape}")
    f = f.astype(np.float32, copy=False)
    if not np.all(np.isfinite(f)) or (f.size and float(np.abs(f).max()) > 1e37):
        raise ParameterError("frames contain NaN, infinite or float32-overflowing values")
    return f


def _local(part: Part, world: np.ndarray) -> np.ndarray:
    """Positions (K, n, 3) of the part's vertices in its node's local frame (the input itself for an identity
    node, which keeps a large export at one float32 copy of its frames)."""
    m = part.to_local
    if np.array_equal(m, np.eye(4)):
        return world
    return (world.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def _normals(layout: Layout, frames: np.ndarray) -> np.ndarray:
    """Unit normals (K, V, 3) in world space, area-weighted over the welded surface (compiled, one pass per
    frame): a glTF source's weld, else :func:`~.weld.smooth_groups` of the frames."""
    if not len(layout.faces):
        return np.zeros(frames.shape, np.float32)
    weld = layout.weld if layout.weld is not None else smooth_groups(frames, layout.faces)
    if weld is None:
        return unit_normals_frames(frames, layout.faces)
    first = np.zeros(int(weld.max()) + 1, np.int64)
    first[weld[::-1]] = np.arange(len(weld))[::-1]
    welded = unit_normals_frames(frames[:, first], weld[layout.faces])
    return welded[:, weld]


def _local_normals(part: Part, normals: np.ndarray) -> np.ndarray:
    """World normals (K, n, 3) turned into the node's local frame (inverse transpose), unit length."""
    linear = np.linalg.inv(part.to_local[:3, :3])  # local -> world linear map
    out = normals @ linear
    length = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


def _assemble(doc: dict[str, Any], views: list[bytes], compress: bool) -> bytes:
    offset, chunks = 0, []
    for view, raw in zip(doc.get("bufferViews", []), views, strict=True):
        view["byteOffset"] = offset
        pad = -len(raw) % 4
        chunks.append(raw + b"\0" * pad)
        offset += len(raw) + pad
    binary = b"".join(chunks)
    if offset:
        doc["buffers"] = [{"byteLength": offset}]
    for key in ("bufferViews", "accessors"):
        if not doc.get(key):
            doc.pop(key, None)
    return compress_glb(doc, binary) if compress and offset else pack_glb(doc, binary)


def layout_frame_glb(layout: Layout, positions: np.ndarray, *, normals: np.ndarray | None = None) -> bytes:
    """One frame (V, 3) world positions as GLB in the layout: float32 POSITION (exact bounds) and unit NORMAL
    per primitive, in each node's local frame (``normals`` (1, V, 3) world normals, else computed)."""
    world = _check_frames(np.asarray(positions)[None], layout)
    normals = _normals(layout, world) if normals is None else normals
    doc, views = copy.deepcopy(layout.doc), list(layout.views)
    for part in layout.parts:
        for slot in part.slots:
            attrs = doc["meshes"][slot.mesh]["primitives"][slot.prim]["attributes"]
            local = _local(part, world[:, slot.start: slot.stop])[0].astype(np.float32)
            attrs["POSITION"] = add_accessor(doc, views, local, "VEC3", ARRAY_BUFFER, minmax=True)
            if slot.normals:
                n = _local_normals(part, normals[:, slot.start: slot.stop].astype(np.float64))[0]
                attrs["NORMAL"] = add_accessor(doc, views, n.astype(np.float32), "VEC3", ARRAY_BUFFER)
    return _assemble(doc, views, compress=False)


class LayoutFrames:
    """:func:`layout_frame_glb` for one layout, fast for many frames (the service's frame route): the JSON
    around the data, the kept source bytes (UVs, indices, images) and the normals' incidence are made once;
    each call computes normals and local positions, fills one preallocated GLB and updates the bounds."""

    def __init__(self, layout: Layout) -> None:
        from .glb import unpack_glb
        from .normals import FaceNormals

        self.layout = layout
        zero = np.zeros((1, layout.n_vertices, 3), np.float32)
        zero[0, :, 2] = 1.0  # placeholder normals must be unit for the template's sake only
        doc, binary = unpack_glb(layout_frame_glb(layout, zero[0], normals=zero))
        self._doc, self._binary = doc, binary or b""
        self._slots = []
        for part in layout.parts:
            for slot in part.slots:
                attrs = doc["meshes"][slot.mesh]["primitives"][slot.prim]["attributes"]
                offsets = {name: doc["bufferViews"][doc["accessors"][attrs[name]]["bufferView"]]["byteOffset"]
                           for name in ("POSITION", "NORMAL") if name in attrs}
                self._slots.append((part, slot, attrs["POSITION"], offsets))
        weld = layout.weld
        if weld is None:
            self._first, faces = None, layout.faces
        else:
            self._first = np.zeros(int(weld.max()) + 1, np.int64)
            self._first[weld[::-1]] = np.arange(len(weld))[::-1]
            faces = weld[layout.faces]
        n = layout.n_vertices if weld is None else len(self._first)
        self._normals = FaceNormals(faces, n) if len(faces) else None

    def __call__(self, positions: np.ndarray) -> bytes:
        """GLB bytes of one frame: world positions (V, 3) of the layout's vertices."""
        world = _check_frames(np.asarray(positions)[None], self.layout)[0]
        normals = None
        if self._normals is not None:
            normals = self._normals(world if self._first is None else world[self._first])
            if self._first is not None:
                normals = normals[self.layout.weld]
        accessors = list(self._doc["accessors"])
        out = bytearray(self._binary)
        for part, slot, pos_acc, offsets in self._slots:
            local = _local(part, world[None, slot.start: slot.stop])[0]
            n = slot.stop - slot.start
            np.frombuffer(out, np.float32, 3 * n, offsets["POSITION"]).reshape(-1, 3)[:] = local
            accessors[pos_acc] = {**accessors[pos_acc], **minmax_of(local)}
            if "NORMAL" in offsets and normals is not None:
                nrm = normals[slot.start: slot.stop]
                if not np.array_equal(part.to_local, np.eye(4)):
                    nrm = _local_normals(part, nrm[None].astype(np.float64))[0]
                np.frombuffer(out, np.float32, 3 * n, offsets["NORMAL"]).reshape(-1, 3)[:] = nrm
        return pack_glb({**self._doc, "accessors": accessors}, bytes(out))


def _bounds(values: np.ndarray, axis: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Exact (min, max) of (..., 3) values per component, over ``axis`` (default: all but the last). One
    strided reduction per component: numpy reduces over rows of three values about 20x slower."""
    lo = [values[..., c].min(axis=axis) for c in range(values.shape[-1])]
    hi = [values[..., c].max(axis=axis) for c in range(values.shape[-1])]
    return np.stack(lo, axis=-1), np.stack(hi, axis=-1)


MIN_BITS, MAX_BITS, FALLBACK_BITS = 8, 15, 14
"""A grid asked for by its error keeps between 8 and 15 bits of the extent (int16 holds 15); without an error
either, 14 bits."""


class _Grid:
    """Integer grid of one part: origin + step * q with q in [0, extent / step] over every frame, the step
    ``extent / (2**bits - 1)`` or ``step`` (kept within MIN_BITS..MAX_BITS of the extent)."""

    def __init__(self, local: np.ndarray, bits: int | None, step: float | None = None) -> None:
        self.origin, top = _bounds(local)
        extent = float((top - self.origin).max())
        if extent <= 0:
            self.step = 1.0
        elif step is None:
            self.step = extent / (2 ** (FALLBACK_BITS if bits is None else bits) - 1)
        else:
            self.step = min(max(float(step), extent / (2**MAX_BITS - 1)), extent / (2**MIN_BITS - 1))
        # float32 arithmetic: its rounding is ~1e-3 of a step at 14 bits; int16 holds 0..2**15 - 1
        self.q = np.rint((local - self.origin.astype(np.float32)) / np.float32(self.step)).astype(np.int16)

    def node(self) -> dict[str, Any]:
        """Translation and uniform scale that map grid values back to local coordinates."""
        return {"translation": [float(x) for x in self.origin], "scale": [float(self.step)] * 3}


def _padded(values: np.ndarray, dtype: type, width: int) -> np.ndarray:
    """(..., 3) values as ``dtype`` padded to ``width`` components (4-byte aligned vertex strides)."""
    out = np.zeros((*values.shape[:-1], width), dtype)
    out[..., :3] = values
    return out


def _target_views(doc: dict, views: list[bytes], data: np.ndarray, stride: int) -> list[tuple[int, int]]:
    """Put (K, n, w) per-target data into as few views as allowed; (view, byte offset) of each target."""
    k, n = data.shape[:2]
    per_view = max(1, TARGET_VIEW_VALUES // max(1, n * stride))
    out = []
    for first in range(0, k, per_view):
        chunk = np.ascontiguousarray(data[first: first + per_view])
        view = add_view(doc, views, chunk.tobytes(), ARRAY_BUFFER, stride)
        out.extend((view, i * n * stride) for i in range(len(chunk)))
    return out


def _add_targets(doc: dict, views: list[bytes], positions: np.ndarray, normals: np.ndarray | None,
                 opts: PackOptions) -> tuple[int, int | None, list[dict]]:
    """Base POSITION (and NORMAL) accessors and one morph target per frame (deltas from frame 0) of one
    primitive; positions (K, n, 3) grid ints or floats, normals (K, n, 3) unit."""
    k, n = positions.shape[:2]
    if opts.quantize:
        base = _padded(positions[0], np.int16, 4)
        pos = add_accessor(doc, views, base, "VEC3", ARRAY_BUFFER, minmax=False,
                           view=add_view(doc, views, base.tobytes(), ARRAY_BUFFER, 8))
        doc["accessors"][pos].update(minmax_of(positions[0]))
        delta = (positions - positions[:1]).astype(np.int16)
        lo, hi = _bounds(delta, axis=1)  # exact bounds of every target, (K, 3)
        # a target whose deltas fit in a byte is written as BYTE (as gltfpack does): half the raw bytes, and
        # meshopt's codec spends nothing on the high bytes it no longer has
        small = (lo >= -127).all(axis=1) & (hi <= 127).all(axis=1)
        kinds = [(small, np.int8, 4), (~small, np.int16, 8)]
    else:
        pos = add_accessor(doc, views, positions[0].astype(np.float32), "VEC3", ARRAY_BUFFER, minmax=True)
        delta = (positions - positions[:1]).astype(np.float32)
        lo, hi = _bounds(delta, axis=1)
        kinds = [(np.ones(k, bool), np.float32, 12)]
    placed: list[tuple[int, int, type] | None] = [None] * k
    for which, dtype, stride in kinds:
        idx = np.flatnonzero(which)
        if not len(idx):
            continue
        part = delta if len(idx) == k else delta[idx]
        data = part if dtype == np.float32 else _padded(part, dtype, 4)  # 4-byte aligned vertex strides
        for i, (view, off) in zip(idx, _target_views(doc, views, data, stride), strict=True):
            placed[i] = (view, off, dtype)
    targets: list[dict] = []
    for i, (view, off, dtype) in enumerate(placed):  # type: ignore[misc]
        acc = add_accessor(doc, views, np.zeros((n, 3), dtype), "VEC3", view=view, byte_offset=off)
        doc["accessors"][acc].update(minmax_of(np.stack([lo[i], hi[i]])))
        targets.append({"POSITION": acc})
    nrm = None
    if normals is not None:
        if opts.quantize:
            b = _padded(np.rint(normals[0] * 127), np.int8, 4)
            nrm = add_accessor(doc, views, np.zeros((n, 3), np.int8), "VEC3", normalized=True,
                               view=add_view(doc, views, b.tobytes(), ARRAY_BUFFER, 4))
        else:
            nrm = add_accessor(doc, views, normals[0].astype(np.float32), "VEC3", ARRAY_BUFFER)
        if opts.normals and k > 1:
            d = normals - normals[:1]
            if opts.quantize:
                nd, stride, dt = _padded(np.rint(np.clip(d, -1, 1) * 127), np.int8, 4), 4, np.int8
            else:
                nd, stride, dt = d.astype(np.float32), 12, np.float32
            for target, (view, off) in zip(targets, _target_views(doc, views, nd, stride), strict=True):
                target["NORMAL"] = add_accessor(doc, views, np.zeros((n, 3), dt), "VEC3",
                                                normalized=opts.quantize, view=view, byte_offset=off)
    return pos, nrm, targets


def _quantised_normals(normals: np.ndarray) -> np.ndarray:
    """Unit normals rounded to normalized bytes and back (what a viewer sees), for the deltas' reference."""
    return np.rint(normals * 127) / 127


def _slot_faces(layout: Layout, slot: Slot) -> np.ndarray:
    """The slot's triangles (T, 3) over its own vertices (0 = the slot's first)."""
    f = layout.faces
    inside = (f[:, 0] >= slot.start) & (f[:, 0] < slot.stop)
    return f[inside] - slot.start


def _write_slot(doc: dict, views: list[bytes], layout: Layout, part: Part, slot: Slot, pos: np.ndarray,
                normals: np.ndarray | None, opts: PackOptions) -> None:
    """One primitive's POSITION, NORMAL and morph targets from its positions (K, n, 3) (grid or local) and
    the world ``normals`` (K, V, 3) of every clip vertex (None: none written), welded unless ``opts`` say
    not."""
    prim = doc["meshes"][slot.mesh]["primitives"][slot.prim]
    nrm = None
    if slot.normals and normals is not None:
        nrm = normals[:, slot.start: slot.stop].astype(np.float64)  # unit already
        if not np.array_equal(part.to_local, np.eye(4)):  # an identity node keeps them as they are
            nrm = _local_normals(part, nrm)
        if opts.quantize:
            nrm = _quantised_normals(nrm)
    if opts.weld and prim.get("mode", 4) == 4:
        pos, nrm = _welded(doc, views, prim, layout, slot, pos, nrm, opts)
    p_acc, n_acc, targets = _add_targets(doc, views, pos, nrm, opts)
    prim["attributes"]["POSITION"] = p_acc
    if n_acc is not None:
        prim["attributes"]["NORMAL"] = n_acc
    prim["targets"] = targets


def _welded(doc: dict, views: list[bytes], prim: dict, layout: Layout, slot: Slot, pos: np.ndarray,
            nrm: np.ndarray | None, opts: PackOptions) -> tuple[np.ndarray, np.ndarray | None]:
    """One slot's positions (K, n, 3) and normals after :func:`~.weld.weld_primitive` (which rewrites
    ``prim``); the weld compares normals as written: bytes when quantised, float32 otherwise, and only the
    first frame's without normal targets."""
    written = None
    if nrm is not None:
        shown = nrm if opts.normals else nrm[:1]
        written = np.rint(shown * 127).astype(np.int8) if opts.quantize else shown.astype(np.float32)
    keep = weld_primitive(doc, views, prim, pos, written, _slot_faces(layout, slot), slot.start)
    if keep is None:
        return pos, nrm
    return pos[:, keep], None if nrm is None else nrm[:, keep]


def _mesh_node(doc: dict, part: Part, grid: _Grid | None, name: str | None, own: bool) -> int:
    """The node that holds the part's mesh: the part's own node when pdeanim made it (``own``, a plain layout)
    and it is a leaf without a transform, else a new child, so a source's node transforms stay as they
    were."""
    node = doc["nodes"][part.node]
    if grid is None:
        return part.node
    plain = own and not any(k in node for k in ("matrix", "translation", "rotation", "scale", "children"))
    if plain:
        node.update(grid.node())
        return part.node
    child = {"mesh": node.pop("mesh"), **grid.node()}
    if name:
        child["name"] = name
    doc["nodes"].append(child)
    node["children"] = [len(doc["nodes"]) - 1, *node.get("children", [])]  # first: keeps depth-first order
    return len(doc["nodes"]) - 1


def layout_animation_glb(layout: Layout, frames: np.ndarray, key_times: np.ndarray, key_target: np.ndarray,
                         n_targets: int, *, options: PackOptions | None = None,
                         names: Sequence[str] | None = None, loop: bool = False) -> bytes:
    """Frames (K, V, 3) world positions as morph targets 0..n_targets-1 of every mesh in the layout, with a
    LINEAR ``weights`` animation whose key i (time ``key_times[i]``, float32 strictly increasing) shows
    target ``key_target[i]`` (one-hot). ``names`` go to each mesh's ``extras.targetNames``."""
    opts = options or PackOptions()
    world = _check_frames(frames, layout)[:n_targets]
    # a plain (or OBJ) mesh whose vertex normals are its face normals is flat-shaded: no NORMAL, as a glTF
    # source without normals (viewers then compute the same flat normals), and its corners can weld
    flat = layout.source != "gltf" and flat_shaded(world[0], layout.faces)
    normals = _normals(layout, world) if any(s.normals for s in layout.slots) and not flat else None
    doc, views = copy.deepcopy(layout.doc), list(layout.views)
    holders = []
    for part in layout.parts:
        local = _local(part, world[:, part.slots[0].start: part.slots[-1].stop]) if part.slots else None
        grid = None
        if opts.quantize and local is not None:
            stretch = float(np.linalg.norm(np.linalg.inv(part.to_local[:3, :3]), 2))  # local -> world
            grid = _Grid(local, opts.position_bits, opts.grid_step(stretch))
        first = part.slots[0].start if part.slots else 0
        for slot in part.slots:
            a, b = slot.start - first, slot.stop - first
            pos = grid.q[:, a:b] if grid is not None else local[:, a:b]
            _write_slot(doc, views, layout, part, slot, pos, normals, opts)
        mesh = doc["meshes"][part.mesh]
        mesh["weights"] = [0.0] * n_targets
        if names is not None:
            mesh.setdefault("extras", {})["targetNames"] = [str(x) for x in names][:n_targets]
        holders.append(_mesh_node(doc, part, grid, mesh.get("name"), own=layout.source != "gltf"))
    prims = [(doc["meshes"][s.mesh]["primitives"][s.prim], s.start) for s in layout.slots]
    map_all_or_none(doc, views, prims)
    if opts.quantize:
        for key in ("extensionsUsed", "extensionsRequired"):
            doc[key] = [*[e for e in doc.get(key, []) if e != QUANT], QUANT]
    views = drop_unused(doc, views)  # the source indices and attributes that welding replaced
    weights = np.zeros((len(key_times), n_targets), np.float32)
    weights[np.arange(len(key_times)), key_target] = 1.0
    t_acc = add_accessor(doc, views, np.asarray(key_times, np.float32).reshape(-1, 1), "SCALAR", minmax=True)
    w_acc = add_accessor(doc, views, weights.reshape(-1, 1), "SCALAR")
    doc["animations"] = [{
        "name": "pdeanim", "extras": {"loop": bool(loop)},
        "samplers": [{"input": t_acc, "output": w_acc, "interpolation": "LINEAR"} for _ in holders],
        "channels": [{"sampler": i, "target": {"node": h, "path": "weights"}}
                     for i, h in enumerate(holders)]}]
    return _assemble(doc, views, opts.compress)
