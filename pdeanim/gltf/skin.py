"""Skinned meshes and linear blend skinning per glTF 2.0: joint matrix = joint world matrix x inverse bind
matrix, vertex = sum of weight x joint matrix x bind-space position. Weights that do not sum to 1 are
renormalised (and counted in a report), never passed on. Used by the animated-poses reader and by cyclic
walk/run cycles that drive hip and foot joints."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, MeshInputError
from .document import GltfDocument, load_document, malformed_as
from .primitives import read_primitive
from .sampling import trs_matrices
from .scene import node_parents, scene_order, world_matrices

WEIGHT_TOLERANCE = 1e-4  # |sum - 1| above this counts as "renormalised"
_CHUNK_VALUES = 20_000_000  # cap on V * frames * 12 blended-matrix values held at once


def normalise_weights(weights: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """Weights (V, n) scaled to sum to 1 per vertex; negative weights are zeroed. Returns them and a report
    (counts of renormalised, negative and all-zero vertices, the largest deviation of a sum from 1)."""
    w = np.asarray(weights, np.float64)
    negative = w < 0
    w = np.where(negative, 0.0, w)
    total = w.sum(axis=1)
    zero = total <= 0
    off = (np.abs(total - 1.0) > WEIGHT_TOLERANCE) & ~zero
    out = w / np.where(zero, 1.0, total)[:, None]
    report = {"vertices": int(len(w)), "renormalised": int(off.sum()),
              "negative_weights": int(negative.any(axis=1).sum()), "zero_weight_vertices": int(zero.sum()),
              "max_sum_deviation": float(np.abs(total - 1.0).max()) if len(w) else 0.0}
    return out, report


def blend(points: np.ndarray, joint_matrices: np.ndarray, joints: np.ndarray, weights: np.ndarray,
          fallback: np.ndarray | None = None) -> np.ndarray:
    """Linear blend skinning of points (V, 3) or (K, V, 3) with joint matrices (K, J, 4, 4), per-vertex joint
    indices (V, n) and normalised weights (V, n); vertices whose weights are all 0 follow ``fallback``
    (K, 4, 4) (identity when None). Returns (K, V, 3) float64; one sparse product per chunk of frames."""
    jm = np.asarray(joint_matrices, np.float64)
    k, n_joints = jm.shape[:2]
    v = len(joints)
    if joints.size and (joints.min() < 0 or joints.max() >= n_joints):
        raise InputError(f"skin joint indices must lie in [0, {n_joints})")
    fb = np.broadcast_to(np.eye(4) if fallback is None else fallback, (k, 4, 4))
    zero = weights.sum(axis=1) <= 0
    rows = np.concatenate([np.repeat(np.arange(v), joints.shape[1]), np.flatnonzero(zero)])
    cols = np.concatenate([joints.ravel(), np.full(int(zero.sum()), n_joints)])
    vals = np.concatenate([weights.ravel(), np.ones(int(zero.sum()))])
    w = sp.csr_matrix((vals, (rows, cols)), shape=(v, n_joints + 1))
    mats = np.concatenate([jm, fb[:, None]], axis=1)[:, :, :3, :]  # (K, J+1, 3, 4)
    pts = np.broadcast_to(np.asarray(points, np.float64), (k, v, 3))
    out = np.empty((k, v, 3))
    step = max(1, _CHUNK_VALUES // max(12 * v, 1))
    for s in range(0, k, step):
        e = min(k, s + step)
        m = mats[s:e].transpose(1, 0, 2, 3).reshape(n_joints + 1, -1)  # (J+1, Kc*12)
        b = np.asarray(w @ m).reshape(v, e - s, 3, 4).transpose(1, 0, 2, 3)  # (Kc, V, 3, 4)
        out[s:e] = np.einsum("kvab,kvb->kva", b[..., :3], pts[s:e]) + b[..., 3]
    return out


@dataclass
class SkinnedMesh:
    """A skinned glTF mesh at its bind pose.

    rest_vertices (V, 3) f64 bind-space positions (primitives concatenated), faces (T, 3) i64;
    joint_names (J,), joint_nodes (J,) glTF node indices, joint_parents (J,) index of the nearest joint
    ancestor or -1; rest_translations (J, 3), rest_rotations (J, 4) xyzw, rest_scales (J, 3) local TRS;
    parent_offsets (J, 4, 4) transforms of non-joint nodes between a joint and its joint parent (or the
    world, for roots); inverse_bind (J, 4, 4); vertex_joints (V, n) i64; vertex_weights (V, n) f64 summing
    to 1 (0 for unskinned vertices, which follow mesh_matrix (4, 4)); weight_report from normalise_weights.
    """

    rest_vertices: np.ndarray
    faces: np.ndarray
    joint_names: list[str]
    joint_nodes: np.ndarray
    joint_parents: np.ndarray
    rest_translations: np.ndarray
    rest_rotations: np.ndarray
    rest_scales: np.ndarray
    parent_offsets: np.ndarray
    inverse_bind: np.ndarray
    vertex_joints: np.ndarray
    vertex_weights: np.ndarray
    mesh_matrix: np.ndarray
    weight_report: dict[str, Any] = field(default_factory=dict)

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return len(self.joint_names)

    def joint_index(self, key: int | str) -> int:
        """Index of a joint given by index or name."""
        if isinstance(key, str):
            if key not in self.joint_names:
                raise MeshInputError(f"no joint named {key!r}; joints: {', '.join(self.joint_names)}")
            return self.joint_names.index(key)
        if not 0 <= int(key) < self.n_joints:
            raise MeshInputError(f"joint index {key} out of range [0, {self.n_joints})")
        return int(key)


def inverse_binds(gd: GltfDocument, skin: dict) -> np.ndarray:
    """(J, 4, 4) inverse bind matrices of a skin (identity when the accessor is absent)."""
    n = len(skin.get("joints", []))
    if "inverseBindMatrices" not in skin:
        return np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    ibm = gd.matrices(skin["inverseBindMatrices"])
    if len(ibm) != n:
        raise gd.error(f"skin has {n} joints but {len(ibm)} inverse bind matrices")
    return ibm


def _joint_hierarchy(gd: GltfDocument, joint_nodes: np.ndarray, rest_world: np.ndarray):
    """Nearest joint ancestor of each joint and the offset matrix from it (or from the world)."""
    parent = node_parents(gd)
    slot = {int(n): j for j, n in enumerate(joint_nodes)}
    parents = np.full(len(joint_nodes), -1, np.int64)
    offsets = np.empty((len(joint_nodes), 4, 4))
    for j, node in enumerate(joint_nodes):
        p = parent[node]
        while p >= 0 and int(p) not in slot:
            p = parent[p]
        parents[j] = slot[int(p)] if p >= 0 else -1
        par_world = rest_world[parent[node]] if parent[node] >= 0 else np.eye(4)
        offsets[j] = par_world if p < 0 else np.linalg.solve(rest_world[p], par_world)
    return parents, offsets


def _mesh_node(gd: GltfDocument, node: int | None) -> int:
    if node is not None:
        n = gd.item("nodes", node)
        if "mesh" not in n or "skin" not in n:
            raise gd.error(f"node {node} is not a skinned mesh node")
        return node
    for n in scene_order(gd):
        if "mesh" in gd.list("nodes")[n] and "skin" in gd.list("nodes")[n]:
            return n
    raise gd.error("the glTF file has no skinned mesh (no node with both a mesh and a skin)")


def load_skinned(source: str | Path | bytes | GltfDocument, node: int | None = None) -> SkinnedMesh:
    """The skinned mesh of ``node`` (the first skinned mesh node of the default scene when None)."""
    gd = source if isinstance(source, GltfDocument) else load_document(source, MeshInputError)
    with malformed_as(gd.error):
        return _load_skinned(gd, node)


def _load_skinned(gd: GltfDocument, node: int | None) -> SkinnedMesh:
    n = _mesh_node(gd, node)
    spec = gd.list("nodes")[n]
    skin = gd.item("skins", spec["skin"])
    joint_nodes = np.asarray(skin.get("joints", []), np.int64)
    if not len(joint_nodes):
        raise gd.error(f"skin {spec['skin']} has no joints")
    prims = [read_primitive(gd, p) for p in gd.item("meshes", spec["mesh"]).get("primitives", [])]
    if not prims:
        raise gd.error(f"mesh {spec['mesh']} has no primitives")
    offsets = np.cumsum([0] + [len(p.positions) for p in prims])
    width = max(p.joints.shape[1] for p in prims)
    pad = [(p.joints, p.weights) if p.joints.shape[1] == width else
           (np.pad(p.joints, ((0, 0), (0, width - p.joints.shape[1]))),
            np.pad(p.weights, ((0, 0), (0, width - p.weights.shape[1])))) for p in prims]
    weights, report = normalise_weights(np.concatenate([w for _, w in pad]))
    rest_world = world_matrices(gd, {}, np.zeros(1))[0]
    parents, offs = _joint_hierarchy(gd, joint_nodes, rest_world)
    nodes = gd.list("nodes")
    return SkinnedMesh(
        rest_vertices=np.concatenate([p.positions for p in prims]),
        faces=np.concatenate([p.faces + o for p, o in zip(prims, offsets, strict=False)]),
        joint_names=[str(nodes[j].get("name", f"joint{i}")) for i, j in enumerate(joint_nodes)],
        joint_nodes=joint_nodes, joint_parents=parents,
        rest_translations=np.array([nodes[j].get("translation", [0, 0, 0]) for j in joint_nodes], np.float64),
        rest_rotations=np.array([nodes[j].get("rotation", [0, 0, 0, 1]) for j in joint_nodes], np.float64),
        rest_scales=np.array([nodes[j].get("scale", [1, 1, 1]) for j in joint_nodes], np.float64),
        parent_offsets=offs, inverse_bind=inverse_binds(gd, skin),
        vertex_joints=np.concatenate([j for j, _ in pad]), vertex_weights=weights,
        mesh_matrix=rest_world[n], weight_report=report)


def _local_trs(
    skinned: SkinnedMesh, overrides: Mapping[int | str, Mapping[str, Any]]
) -> tuple[np.ndarray, ...]:
    """Per-joint translation, rotation, scale with overrides applied; batched (K, J, .) when any is (K, .)."""
    parts = {"translation": skinned.rest_translations, "rotation": skinned.rest_rotations,
             "scale": skinned.rest_scales}
    batch = 1
    for spec in overrides.values():
        for value in spec.values():
            a = np.asarray(value, np.float64)
            batch = max(batch, len(a)) if a.ndim == 2 else batch
    batched = any(np.asarray(v).ndim == 2 for s in overrides.values() for v in s.values())
    out = {k: np.broadcast_to(v, (batch, *v.shape)).copy() for k, v in parts.items()}
    for key, spec in overrides.items():
        j = skinned.joint_index(key)
        for path, value in spec.items():
            if path not in out:
                raise MeshInputError(f"unknown joint property {path!r} (use translation, rotation, scale)")
            out[path][:, j] = np.asarray(value, np.float64)
    return out["translation"], out["rotation"], out["scale"], batched


def joint_world_matrices(
    skinned: SkinnedMesh, local_trs_overrides: Mapping[int | str, Mapping[str, Any]] | None = None
) -> np.ndarray:
    """World matrices of every joint, (J, 4, 4), or (K, J, 4, 4) when an override value is batched.

    ``local_trs_overrides`` maps a joint name or index to replacement local ``translation`` (3,) or (K, 3),
    ``rotation`` xyzw (4,) or (K, 4) and/or ``scale``; other joints keep their rest TRS.
    """
    t, r, s, batched = _local_trs(skinned, local_trs_overrides or {})
    local = trs_matrices(t, r, s)  # (K, J, 4, 4)
    world = np.empty_like(local)
    depth = np.zeros(skinned.n_joints, np.int64)
    for j in range(skinned.n_joints):
        p = skinned.joint_parents[j]
        while p >= 0:
            depth[j] += 1
            p = skinned.joint_parents[p]
    for j in np.argsort(depth, kind="stable"):
        p = skinned.joint_parents[j]
        base = skinned.parent_offsets[j] if p < 0 else world[:, p] @ skinned.parent_offsets[j]
        world[:, j] = base @ local[:, j]
    return world if batched else world[0]


def skin_vertices(
    skinned: SkinnedMesh, world_matrices: np.ndarray, points: np.ndarray | None = None
) -> np.ndarray:
    """Skinned positions (V, 3) for joint world matrices (J, 4, 4), or (K, V, 3) for (K, J, 4, 4); ``points``
    replaces the bind-space rest vertices (e.g. after morphing)."""
    wm = np.asarray(world_matrices, np.float64)
    single = wm.ndim == 3
    jm = (wm[None] if single else wm) @ skinned.inverse_bind
    out = blend(skinned.rest_vertices if points is None else points, jm, skinned.vertex_joints,
                skinned.vertex_weights, skinned.mesh_matrix)
    return out[0] if single else out
