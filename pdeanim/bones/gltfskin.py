"""The bone layer of a skinned glTF input, from the file's own skeleton: every joint of a skin is a bone
moving its bind-space vertices by the rigid part of (joint world matrix x inverse bind matrix), with the
file's weights (the 4 largest per vertex); meshes without a skin ride on a bone of their node. No
decomposition: what is not rigid (morph targets, scale, more than 4 influences) is left to the residual."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import PosesInputError
from ..gltf.document import load_document, malformed_as
from ..gltf.read import mesh_instances
from ..gltf.scene import animation_tracks, pick_animation, world_matrices
from ..gltf.skin import inverse_binds, normalise_weights
from ..model.bonelayer import MAX_INFLUENCES, BoneMotion
from ..poses import Poses
from .motion import pivots


@dataclass(frozen=True)
class SkinBones:
    """A skinned input's bone motion, its bind-space rest pose (V, 3) (what the bones skin) and its joint
    count (the skins' joints, plus one bone per node that moves unskinned vertices)."""

    motion: BoneMotion
    rest: np.ndarray
    n_joints: int


def skin_bones(source: str | Path | bytes, poses: Poses) -> SkinBones | None:
    """The bone layer of the glTF ``source`` whose animation ``poses`` were read from (same animation and
    frame times, :func:`pdeanim.gltf.read.read_animated_poses`); None when no mesh of it has a skin."""
    gd = load_document(source, PosesInputError)
    with malformed_as(PosesInputError):
        instances = mesh_instances(gd)
        if not any(i.skin is not None and i.primitive.joints.shape[1] for i in instances):
            return None
        _, anim = pick_animation(gd, (poses.meta.get("animation") or {}).get("index"))
        world = world_matrices(gd, animation_tracks(gd, anim), np.asarray(poses.times, np.float64))
        bones: dict[tuple, np.ndarray] = {}  # key -> (F, 4, 4) matrices moving bind-space positions
        rest, index, weight = [], [], []
        for inst in instances:
            p = inst.primitive
            rest.append(np.asarray(p.positions, np.float64))
            node_key = ("node", inst.node)
            if inst.skin is None or not p.joints.shape[1]:
                bones.setdefault(node_key, world[:, inst.node])
                index.append(np.full((len(p.positions), 1), list(bones).index(node_key)))
                weight.append(np.ones((len(p.positions), 1)))
                continue
            skin = gd.item("skins", inst.skin)
            joints = np.asarray(skin.get("joints", []), np.int64)
            if p.joints.size and (p.joints.min() < 0 or p.joints.max() >= len(joints)):
                raise gd.error(f"skin of node {inst.node}: joint indices must lie in [0, {len(joints)})")
            jm = world[:, joints] @ inverse_binds(gd, skin)
            for j in range(len(joints)):
                bones.setdefault(("skin", inst.skin, j), jm[:, j])
            ids = np.array([list(bones).index(("skin", inst.skin, j)) for j in range(len(joints))])
            w, _ = normalise_weights(p.weights)
            j_idx = ids[np.asarray(p.joints, np.int64)]
            zero = w.sum(axis=1) <= 0
            if zero.any():
                bones.setdefault(node_key, world[:, inst.node])
                j_idx[zero, 0], w[zero, 0] = list(bones).index(node_key), 1.0
            index.append(j_idx)
            weight.append(w)
    if sum(len(r) for r in rest) != poses.n_vertices:
        raise PosesInputError(f"the glTF's meshes have {sum(len(r) for r in rest)} vertices, the poses "
                              f"{poses.n_vertices}")
    n_joints = sum(1 for k in bones if k[0] == "skin")
    rest_v = np.concatenate(rest)
    idx, w = _top_influences(index, weight)
    M = np.stack(list(bones.values()), axis=1)  # (F, B, 4, 4)
    return SkinBones(rigid_motion(M, rest_v, idx, w), rest_v, n_joints)


def _top_influences(index: list[np.ndarray], weight: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(V, K) the largest MAX_INFLUENCES influences of every vertex, weights renormalised to sum 1."""
    width = max(i.shape[1] for i in index)
    idx = np.concatenate([np.pad(i, ((0, 0), (0, width - i.shape[1]))) for i in index])
    w = np.concatenate([np.pad(x, ((0, 0), (0, width - x.shape[1]))) for x in weight])
    order = np.argsort(-w, axis=1, kind="stable")[:, :MAX_INFLUENCES]
    idx, w = np.take_along_axis(idx, order, 1), np.take_along_axis(w, order, 1)
    w = w / w.sum(axis=1, keepdims=True)
    return np.where(w > 0, idx, idx[:, :1]), w


def rigid_motion(M: np.ndarray, rest: np.ndarray, index: np.ndarray, weight: np.ndarray) -> BoneMotion:
    """BoneMotion of bone matrices M (F, B, 4, 4): the rotation nearest each linear part (polar
    decomposition), about each bone's pivot (the weighted centroid of its vertices), the translation exact
    at the pivot."""
    F, B = M.shape[:2]
    U, _, Vt = np.linalg.svd(M[..., :3, :3])
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    U[..., :, 2] *= d[..., None]
    R = U @ Vt
    pivot = pivots(rest, index, weight, B)
    T = np.einsum("fbij,bj->fbi", M[..., :3, :3], pivot) + M[..., :3, 3] - pivot[None]
    rotvec = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(F, B, 3)
    return BoneMotion(pivot, index.astype(np.int64), weight, rotvec, T)
