"""GLB of a clip with a bone layer (format 1.1, docs/format.md §3.9) as a skinned glTF animation that a
player runs natively (three.js's ``SkinnedMesh`` and ``AnimationMixer``): the rest pose as the bind pose,
one joint per bone (translation c_b + T_b, rotation quat(R_b), inverse bind matrix translate(-c_b)),
JOINTS_0 / WEIGHTS_0 from the bone influences, and per joint a translation and a rotation channel sampled at
the export's key times (LINEAR). A clip whose residual curves are not all zero adds one morph target per key
(the residual moved back into the bind pose, so that skinning the morphed rest gives the clip's positions at
the keys) with a one-hot ``weights`` animation. Positions are float32 (no quantisation, no meshopt)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.clipmodel import DynamicClip
from .glb import ARRAY_BUFFER, GlbBuilder
from .normals import vertex_normals
from .write import _check_faces, _primitive

WEIGHT_SUM_SLACK = 2e-7
"""How far a float32 weight row may sum from 1 before its largest weight takes up the difference."""


def has_bone_layer(clip: object) -> bool:
    """Whether ``clip`` is a dynamic-PDE clip with a bone layer."""
    return isinstance(clip, DynamicClip) and clip.bones is not None


def residual_is_zero(clip: DynamicClip) -> bool:
    """Whether every residual curve knot is 0 (the clip is its bone layer alone)."""
    return not np.any(clip.coef.knots)


def skinned_animation_glb(clip: DynamicClip, seconds: np.ndarray, t: np.ndarray, *, normals: bool = True,
                          names: list[str] | None = None) -> bytes:
    """The skinned animation GLB of ``clip`` keyed at ``seconds`` (K,) (normalised times ``t`` (K,)); for a
    looping clip the last key is the first pose (t = 1 wraps to 0), as in the morph-target export."""
    player = clip.bones
    if player is None:
        raise ValueError("skinned_animation_glb needs a clip with a bone layer")
    rest = np.asarray(clip.topo.rest, np.float32)
    V, B = len(rest), player.enc.n_bones
    faces = _check_faces(clip.faces, V)
    channels_t = player.tracks.channels(t)  # (K, B, 6)
    R, T = player.tracks.transforms(t)  # (K, B, 3, 3), (K, B, 3)
    b = GlbBuilder()
    attrs = {"POSITION": b.add_accessor(rest, target=ARRAY_BUFFER, minmax=True)}
    if normals and len(faces):
        attrs["NORMAL"] = b.add_accessor(vertex_normals(rest, faces).astype(np.float32), target=ARRAY_BUFFER)
    joints, weights = _influences(player.index, player.weight, B)
    attrs["JOINTS_0"] = b.add_accessor(joints, target=ARRAY_BUFFER, acc_type="VEC4")
    attrs["WEIGHTS_0"] = b.add_accessor(weights, target=ARRAY_BUFFER, acc_type="VEC4")
    prim = _primitive(b, attrs, faces, V)
    mesh: dict = {"primitives": [prim], "name": "pdeanim"}
    key_times = (np.asarray(seconds, np.float64) - seconds[0]).astype(np.float32)
    t_acc = b.add_accessor(key_times, minmax=True, acc_type="SCALAR")
    samplers, channels = [], []
    pivot = player.pivot
    quats = _quaternions(channels_t[..., :3])
    first_joint = 1
    for j in range(B):
        for path, values in (("translation", (pivot[j] + T[:, j]).astype(np.float32)),
                             ("rotation", quats[:, j])):
            samplers.append({"input": t_acc, "output": b.add_accessor(values), "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": first_joint + j, "path": path}})
    if not residual_is_zero(clip):
        n_targets = _add_residual_targets(b, prim, clip, t, R, player)
        w = np.zeros((len(t), n_targets), np.float32)
        w[np.arange(len(t)), _key_targets(len(t), n_targets)] = 1.0
        samplers.append({"input": t_acc, "output": b.add_accessor(w.reshape(-1), acc_type="SCALAR"),
                         "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": "weights"}})
        mesh["weights"] = [0.0] * n_targets
        if names is not None:
            mesh["extras"] = {"targetNames": list(names[:n_targets])}
    ibm = np.tile(np.eye(4, dtype=np.float32), (B, 1, 1))
    ibm[:, 3, :3] = -pivot  # column-major storage: the translation is the 4th column, stored 4th
    ibm_acc = b.add_accessor(ibm.reshape(B, 16), acc_type="MAT4")
    root = first_joint + B
    b.doc["meshes"] = [mesh]
    b.doc["nodes"] = [{"name": "pdeanim", "mesh": 0, "skin": 0}] + [
        {"name": f"bone_{j}", "translation": [float(x) for x in (pivot[j] + T[0, j]).astype(np.float32)],
         "rotation": [float(x) for x in quats[0, j]]} for j in range(B)] + [
        {"name": "skeleton", "children": list(range(first_joint, first_joint + B))}]
    b.doc["skins"] = [{"joints": list(range(first_joint, first_joint + B)), "inverseBindMatrices": ibm_acc,
                       "skeleton": root}]
    b.doc["scenes"] = [{"nodes": [0, root]}]
    b.doc["scene"] = 0
    b.doc["animations"] = [{"name": "pdeanim", "extras": {"loop": bool(clip.looping)}, "samplers": samplers,
                            "channels": channels}]
    return b.to_glb()


def _influences(index: np.ndarray, weight: np.ndarray, n_bones: int) -> tuple[np.ndarray, np.ndarray]:
    """(JOINTS_0 (V, 4) uint8 or uint16, WEIGHTS_0 (V, 4) float32): a vertex's influences on one bone merged
    (glTF forbids a joint twice in a vertex), zero-weight slots pointing at distinct unused joints' slot
    values of 0 weight, rows normalised in float32."""
    V, K = index.shape
    joints = np.zeros((V, 4), np.int64)
    w = np.zeros((V, 4), np.float64)
    joints[:, :K], w[:, :K] = index, weight
    for k in range(1, K):  # merge a repeated bone into its first slot
        for j in range(k):
            same = (joints[:, k] == joints[:, j]) & (w[:, j] > 0) & (w[:, k] > 0)
            w[same, j] += w[same, k]
            w[same, k] = 0.0
    order = np.argsort(-w, axis=1, kind="stable")  # non-zero weights first
    joints, w = np.take_along_axis(joints, order, 1), np.take_along_axis(w, order, 1)
    joints[w == 0] = 0  # zero weights on joint 0 (the validator accepts repeats with zero weight)
    w32 = (w / w.sum(axis=1, keepdims=True)).astype(np.float32)
    off = np.float32(1.0) - w32.sum(axis=1, dtype=np.float32)
    fix = np.abs(off) > WEIGHT_SUM_SLACK
    w32[fix, 0] += off[fix]
    return joints.astype(np.uint8 if n_bones <= 256 else np.uint16), w32


def _quaternions(rotvec: np.ndarray) -> np.ndarray:
    """(K, B, 4) float32 unit quaternions (x, y, z, w) of rotation vectors (K, B, 3), each bone's sign
    continuous over the keys (LINEAR rotation keys interpolate along the short arc between them)."""
    K, B = rotvec.shape[:2]
    q = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat().reshape(K, B, 4)
    for k in range(1, K):
        flip = np.einsum("bi,bi->b", q[k], q[k - 1]) < 0
        q[k, flip] *= -1.0
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.astype(np.float32)


def _key_targets(n_keys: int, n_targets: int) -> np.ndarray:
    """The morph target each key shows (a looping clip's closing key reuses target 0)."""
    keys = np.arange(n_keys)
    return np.where(keys < n_targets, keys, 0)


def _add_residual_targets(b: GlbBuilder, prim: dict, clip: DynamicClip, t: np.ndarray, R: np.ndarray,
                          player) -> int:  # noqa: ANN001 - a BonePlayer
    """One POSITION morph target per key: the residual (positions - skinned base) moved into the bind pose
    by the inverse of the vertex's blended rotation (morphing happens before skinning in glTF). Returns the
    number of targets (a looping clip's last key is its first frame: one fewer)."""
    n_targets = len(t) - 1 if clip.looping and len(t) > 1 else len(t)
    targets = []
    for k in range(n_targets):
        full = np.asarray(clip.evaluate(t[k:k + 1]), np.float64)[0]
        base = player.positions(t[k:k + 1])[0].astype(np.float64)
        M = np.einsum("vk,vkij->vij", player.weight, R[k][player.index])  # blended rotation per vertex
        delta = _solve(M, full - base).astype(np.float32)
        targets.append({"POSITION": b.add_accessor(delta, target=ARRAY_BUFFER, minmax=True)})
    prim["targets"] = targets
    return n_targets


def _solve(M: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(V, 3) x with M x = r per vertex (pseudo-inverse where the blended rotation is singular)."""
    try:
        return np.linalg.solve(M, r[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.einsum("vij,vj->vi", np.linalg.pinv(M), r)
