"""A small skinned test rig built in code: a hip with two three-joint legs (upper leg, knee, foot)."""

from __future__ import annotations

import numpy as np

from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder

# joint name, parent index, local translation (y up, z forward)
JOINTS = [
    ("hip", -1, (0.0, 1.0, 0.0)),
    ("upper_leg.L", 0, (0.15, -0.05, 0.0)),
    ("knee.L", 1, (0.0, -0.45, 0.04)),
    ("foot.L", 2, (0.0, -0.45, -0.04)),
    ("upper_leg.R", 0, (-0.15, -0.05, 0.0)),
    ("knee.R", 4, (0.0, -0.45, 0.04)),
    ("foot.R", 5, (0.0, -0.45, -0.04)),
]


def rest_positions() -> np.ndarray:
    """(J, 3) world positions of the joints at rest."""
    pos = np.zeros((len(JOINTS), 3))
    for j, (_, parent, t) in enumerate(JOINTS):
        pos[j] = (pos[parent] if parent >= 0 else 0.0) + np.asarray(t)
    return pos


def _box(a: np.ndarray, b: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """An 8-vertex box around the segment a-b (12 triangles)."""
    corners = np.array([[x, z] for x in (-half, half) for z in (-half, half)])
    ring = lambda c: np.array([c + [x, 0.0, z] for x, z in corners])  # noqa: E731
    v = np.concatenate([ring(a), ring(b)])
    f = [(0, 1, 5), (0, 5, 4), (1, 3, 7), (1, 7, 5), (3, 2, 6), (3, 6, 7), (2, 0, 4), (2, 4, 6),
         (0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6)]
    return v, np.array(f)


def rig_geometry() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), faces (T, 3), and the joint (V,) each vertex is bound to rigidly."""
    pos = rest_positions()
    bones = [(0, pos[0] + [0.2, 0.1, 0], pos[0] + [-0.2, 0.1, 0], 0.08)]  # pelvis block
    bones += [(j, pos[j], pos[j + 1], 0.05) for j in (1, 2, 4, 5)]
    bones += [(j, pos[j], pos[j] + [0, -0.03, 0.15], 0.04) for j in (3, 6)]  # feet pointing forward
    verts, faces, owner = [], [], []
    for joint, a, b, half in bones:
        v, f = _box(np.asarray(a, float), np.asarray(b, float), half)
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v)
        owner.append(np.full(len(v), joint))
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(owner)


def rig_glb() -> bytes:
    """The rig as a skinned GLB (one mesh node, one skin over the seven joints)."""
    b = GlbBuilder("pdeanim-tests")
    v, f, owner = rig_geometry()
    joints = np.zeros((len(v), 4), np.uint8)
    joints[:, 0] = owner
    weights = np.zeros((len(v), 4), np.float32)
    weights[:, 0] = 1.0
    attrs = {"POSITION": b.add_accessor(v.astype(np.float32), target=ARRAY_BUFFER, minmax=True),
             "JOINTS_0": b.add_accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.add_accessor(weights, target=ARRAY_BUFFER)}
    idx = b.add_accessor(f.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
    ibm = np.broadcast_to(np.eye(4), (len(JOINTS), 4, 4)).copy()
    ibm[:, :3, 3] = -rest_positions()
    ibm_acc = b.add_accessor(ibm.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32), acc_type="MAT4")
    nodes = [{"name": name, "translation": list(t)} for name, _, t in JOINTS]
    for j, (_, parent, _) in enumerate(JOINTS):
        if parent >= 0:
            nodes[parent].setdefault("children", []).append(j)
    nodes.append({"name": "body", "mesh": 0, "skin": 0})
    b.doc.update({"scene": 0, "scenes": [{"nodes": [0, len(JOINTS)]}], "nodes": nodes,
                  "meshes": [{"primitives": [{"attributes": attrs, "indices": idx}]}],
                  "skins": [{"joints": list(range(len(JOINTS))), "inverseBindMatrices": ibm_acc}]})
    return b.to_glb()
