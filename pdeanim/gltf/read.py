"""Read poses from an animated glTF/GLB: morph-target (weights) animation, skinned animation (linear blend
skinning), or meshes moved by node transforms, sampled at a chosen fps over the animation's time range.
Vertices come in file order: scene nodes depth-first, each mesh's primitives in order, concatenated."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import LimitError, MeshInputError, ParameterError, PosesInputError
from ..poses import DEFAULT_FPS, PoseLimits, Poses, make_poses
from .declared import check_declared
from .document import GltfDocument, GltfLimits, load_document, malformed_as
from .primitives import Primitive, read_primitive
from .scene import animation_tracks, morph_weights, pick_animation, scene_order, time_range, world_matrices
from .skin import blend, inverse_binds, normalise_weights


@dataclass
class Instance:
    """One mesh primitive placed by a node: its geometry and the node (and skin) that move it."""

    node: int
    primitive: Primitive
    skin: int | None


def mesh_instances(gd: GltfDocument) -> list[Instance]:
    """Every primitive of every mesh node of the default scene, in traversal order."""
    out = []
    for n in scene_order(gd):
        node = gd.list("nodes")[n]
        if "mesh" not in node:
            continue
        for prim in gd.item("meshes", node["mesh"]).get("primitives", []):
            out.append(Instance(n, read_primitive(gd, prim), node.get("skin")))
    if not out:
        raise gd.error("the glTF scene has no mesh")
    return out


def sample_times(start: float, end: float, fps: float, max_frames: int | None = None) -> np.ndarray:
    """Times from start at 1/fps steps, with the end time included (appended when off the grid)."""
    if not np.isfinite(fps) or fps <= 0:
        raise ParameterError(f"fps must be a positive number, got {fps}")
    span = (end - start) * fps
    if not np.isfinite(span) or (max_frames is not None and span + 1 > max_frames):
        count = int(np.ceil(span)) + 1 if np.isfinite(span) else float(span)
        raise LimitError("frame count", count, max_frames or 0, "PDEANIM_MAX_FRAMES")
    n = int(np.floor(span + 1e-6)) + 1
    t = start + np.arange(n) / fps
    if end - t[-1] > 1e-6 * max(1.0, abs(end)):
        t = np.append(t, end)
    return t


def _check_limits(n_frames: int, n_vertices: int, limits: PoseLimits) -> None:
    if n_frames > limits.max_frames:
        raise LimitError("frame count", n_frames, limits.max_frames, "PDEANIM_MAX_FRAMES")
    if n_vertices > limits.max_vertices:
        raise LimitError("vertex count", n_vertices, limits.max_vertices, "PDEANIM_MAX_VERTICES")
    if n_frames * n_vertices * 3 > limits.max_values:
        raise LimitError("frames x vertices x 3", n_frames * n_vertices * 3, limits.max_values)


def _instance_frames(gd: GltfDocument, inst: Instance, tracks: dict, times: np.ndarray, world: np.ndarray,
                     reports: list) -> np.ndarray:
    """(K, V, 3) positions of one instance: morph, then skin (or the node's world transform)."""
    p = inst.primitive
    w = morph_weights(gd, tracks, inst.node, len(p.targets), times)
    if len(p.targets):
        pts = p.positions[None] + (w @ p.targets.reshape(len(p.targets), -1)).reshape(len(times), -1, 3)
    else:
        pts = np.broadcast_to(p.positions, (len(times), *p.positions.shape))
    if inst.skin is not None and p.joints.shape[1]:
        skin = gd.item("skins", inst.skin)
        joints = np.asarray(skin.get("joints", []), np.int64)
        jm = world[:, joints] @ inverse_binds(gd, skin)
        if p.joints.size and (p.joints.min() < 0 or p.joints.max() >= len(joints)):
            raise gd.error(f"skin of node {inst.node}: joint indices must lie in [0, {len(joints)})")
        weights, report = normalise_weights(p.weights)
        reports.append({"node": inst.node, **report})
        return blend(pts, jm, p.joints, weights, world[:, inst.node])
    m = world[:, inst.node]
    return np.einsum("kab,kvb->kva", m[:, :3, :3], pts) + m[:, None, :3, 3]


def _assemble(instances: list[Instance]) -> tuple[np.ndarray, list[dict]]:
    faces, layout, offset = [], [], 0
    for inst in instances:
        n = len(inst.primitive.positions)
        faces.append(inst.primitive.faces + offset)
        layout.append({"node": inst.node, "first_vertex": offset, "vertices": n})
        offset += n
    return np.concatenate(faces).astype(np.int32), layout


def read_animated_poses(
    source: str | Path | bytes,
    fps: float = DEFAULT_FPS,
    limits: PoseLimits | None = None,
    *,
    animation: int | str | None = None,
    gltf_limits: GltfLimits | None = None,
) -> Poses:
    """Poses (F, V, 3) of a glTF/GLB animation sampled at ``fps`` from its first to its last key time.

    Raises PosesInputError when the file has no animation, no mesh, or is malformed, LimitError when it
    declares more than ``limits`` or ``gltf_limits`` allow (checked before the work); skin weights that do
    not sum to 1 are renormalised and counted in ``meta["skin_weights"]``.
    """
    limits = limits or PoseLimits()
    gd = load_document(source, PosesInputError, gltf_limits)
    with malformed_as(PosesInputError):
        check_declared(gd, limits.max_vertices)
        index, anim = pick_animation(gd, animation)
        tracks = animation_tracks(gd, anim)
        start, end = time_range(tracks)
        times = sample_times(start, end, float(fps), limits.max_frames)
        if len(times) * len(gd.list("nodes")) * 16 > limits.max_values:  # node matrices held per frame
            raise LimitError(
                "frames x nodes x 16", len(times) * len(gd.list("nodes")) * 16, limits.max_values
            )
        instances = mesh_instances(gd)
        n_vertices = sum(len(i.primitive.positions) for i in instances)
        _check_limits(len(times), n_vertices, limits)
        world = world_matrices(gd, tracks, times)
        reports: list[dict] = []
        frames = np.concatenate(
            [_instance_frames(gd, i, tracks, times, world, reports) for i in instances], axis=1
        )
        faces, layout = _assemble(instances)
        kinds = sorted({path for _, path in tracks})
        meta = {"source": "gltf", "animation": {"index": index, "name": anim.get("name"), "channels": kinds},
                "fps": float(fps), "time_range": [start, end], "layout": layout}
    if reports:
        meta["skin_weights"] = reports
    return make_poses(frames, faces, times, meta, limits)


def read_static_mesh(source: str | Path | bytes, gltf_limits: GltfLimits | None = None,
                     max_vertices: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The scene at rest (no animation applied): vertices (V, 3) f64 and faces (T, 3) i32 in file order;
    LimitError when the JSON declares more than the limits allow (checked before the scene is read)."""
    gd = load_document(source, MeshInputError, gltf_limits)
    with malformed_as(MeshInputError):
        check_declared(gd, max_vertices)
        instances = mesh_instances(gd)
        times = np.zeros(1)
        world = world_matrices(gd, {}, times)
        reports: list[dict] = []
        verts = np.concatenate([_instance_frames(gd, i, {}, times, world, reports)[0] for i in instances])
        faces, _ = _assemble(instances)
    return verts, faces
