"""Skinned test rigs built in code: a biped (hip, two three-joint legs), a quadruped (two-bone front legs,
three-bone digitigrade hind legs, spine, neck, head, tail) and a hexapod (three thorax segments, six two-bone
legs, head, abdomen). Each bone is a box bound rigidly to its joint; every foot has a flat pad bound to the
foot joint whose underside lies on the ground (y = 0)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder

PAD = 0.03
"""Half height of a foot pad: foot joints sit this high above the ground."""


@dataclass(frozen=True)
class Rig:
    """joints: (name, parent index, local translation) with y up and z forward; boxes: (joint the box is
    bound to, from point, to point, half width) in rest world coordinates."""

    joints: list[tuple[str, int, tuple[float, float, float]]]
    feet: tuple[str, ...]
    body: tuple[tuple[str, float], ...] = ()

    def positions(self) -> np.ndarray:
        """(J, 3) world positions of the joints at rest."""
        pos = np.zeros((len(self.joints), 3))
        for j, (_, parent, t) in enumerate(self.joints):
            pos[j] = (pos[parent] if parent >= 0 else 0.0) + np.asarray(t)
        return pos

    def index(self, name: str) -> int:
        return [n for n, _, _ in self.joints].index(name)

    def turned(self, degrees: float) -> Rig:
        """The same rig turned about the up axis (it then faces away from +z)."""
        a = np.radians(degrees)
        rot = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
        return Rig([(n, p, tuple(rot @ np.asarray(t))) for n, p, t in self.joints], self.feet, self.body)

    def renamed(self) -> Rig:
        """The same rig with neutral joint names j0, j1, ... (legs must be found from the shape alone)."""
        names = {n: f"j{i}" for i, (n, _, _) in enumerate(self.joints)}
        return Rig([(names[n], p, t) for n, p, t in self.joints], tuple(names[f] for f in self.feet),
                   tuple((names[n], h) for n, h in self.body))


def _leg(name: str, parent: int, start: int, offsets: list[tuple[float, float, float]]) -> list:
    """Joints of one leg: name.0 .. name.k, the first a child of parent; start is the first's index."""
    return [(f"{name}.{i}", parent if i == 0 else start + i - 1, t) for i, t in enumerate(offsets)]


def _mirror(offsets: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    return [(-x, y, z) for x, y, z in offsets]


BIPED = Rig(
    [("hip", -1, (0.0, 1.0, 0.0)),
     ("upper_leg.L", 0, (0.15, -0.05, 0.0)), ("knee.L", 1, (0.0, -0.45, 0.04)),
     ("foot.L", 2, (0.0, -0.47, -0.04)),
     ("upper_leg.R", 0, (-0.15, -0.05, 0.0)), ("knee.R", 4, (0.0, -0.45, 0.04)),
     ("foot.R", 5, (0.0, -0.47, -0.04))],
    ("foot.L", "foot.R"), (("hip", 0.08),))


def _quadruped() -> Rig:
    axial = [("pelvis", -1, (0.0, 1.0, -0.5)), ("spine", 0, (0.0, 0.02, 0.5)), ("chest", 1, (0.0, 0.0, 0.5)),
             ("neck", 2, (0.0, 0.15, 0.15)), ("head", 3, (0.0, 0.12, 0.2)), ("tail.0", 0, (0.0, 0.05, -0.2)),
             ("tail.1", 5, (0.0, 0.04, -0.25))]
    hind = [(0.15, -0.05, 0.0), (0.0, -0.35, 0.12), (0.0, -0.3, -0.15), (0.0, -0.27 + PAD, 0.05)]
    front = [(0.15, -0.07, 0.0), (0.0, -0.45, -0.05), (0.0, -0.47 + PAD, 0.03)]
    joints = list(axial)
    for name, parent, offs in (("hind.L", 0, hind), ("hind.R", 0, _mirror(hind)), ("front.L", 2, front),
                               ("front.R", 2, _mirror(front))):
        joints += _leg(name, parent, len(joints), offs)
    feet = ("hind.L.3", "hind.R.3", "front.L.2", "front.R.2")
    return Rig(joints, feet, (("pelvis", 0.12), ("spine", 0.12), ("chest", 0.12), ("neck", 0.06),
                              ("tail.0", 0.04)))


def _hexapod() -> Rig:
    joints = [("thorax.2", -1, (0.0, 0.5, 0.0)), ("thorax.1", 0, (0.0, 0.0, 0.35)),
              ("thorax.3", 0, (0.0, 0.0, -0.35)), ("head", 1, (0.0, 0.05, 0.25)),
              ("abdomen", 2, (0.0, 0.0, -0.4))]
    feet = []
    for seg, parent, dz in (("1", 1, 0.1), ("2", 0, 0.0), ("3", 2, -0.1)):
        leg = [(0.12, 0.0, 0.0), (0.25, 0.15, dz), (0.2, -0.65 + PAD, dz)]
        for side, offs in (("L", leg), ("R", _mirror(leg))):
            joints += _leg(f"leg{seg}.{side}", parent, len(joints), offs)
            feet.append(f"leg{seg}.{side}.2")
    return Rig(joints, tuple(feet), (("thorax.2", 0.1), ("thorax.1", 0.09), ("thorax.3", 0.09)))


QUADRUPED = _quadruped()
HEXAPOD = _hexapod()
JOINTS = BIPED.joints


def rest_positions() -> np.ndarray:
    """(J, 3) world positions of the biped's joints at rest."""
    return BIPED.positions()


def _box(a: np.ndarray, b: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """An 8-vertex box around the segment a-b (12 triangles, outward)."""
    d = (b - a) / max(np.linalg.norm(b - a), 1e-12)
    u = np.cross(d, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    ring = [half * (su * u + sv * v) for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    verts = np.array([a + r for r in ring] + [b + r for r in ring])
    f = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7)]
    for i in range(4):
        j = (i + 1) % 4
        f += [(i, j, 4 + j), (i, 4 + j, 4 + i)]
    return verts, np.array(f)


def rig_geometry(rig: Rig = BIPED) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), faces (T, 3), and the joint (V,) each vertex is bound to rigidly: a box along every
    bone (bound to the bone's upper joint), one per body joint, and a flat pad under every foot."""
    pos = rig.positions()
    feet = {rig.index(f) for f in rig.feet}
    boxes = []
    for j, (_, parent, _) in enumerate(rig.joints):
        if parent >= 0:  # a bone into a foot stops short of it: the foot's pad alone touches the ground
            end = pos[parent] + 0.8 * (pos[j] - pos[parent]) if j in feet else pos[j]
            boxes.append((parent, pos[parent], end, 0.03))
    for name, half in rig.body:
        j = rig.index(name)
        boxes.append((j, pos[j] + [0, 0, -half], pos[j] + [0, 0, half], half))
    for j in feet:
        boxes.append((j, pos[j] + [0, 0, -0.03], pos[j] + [0, 0, 0.08], PAD))
    verts, faces, owner = [], [], []
    for joint, a, b, half in boxes:
        v, f = _box(np.asarray(a, float), np.asarray(b, float), half)
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v)
        owner.append(np.full(len(v), joint))
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(owner)


def rig_glb(rig: Rig = BIPED) -> bytes:
    """The rig as a skinned GLB (one mesh node, one skin over every joint)."""
    b = GlbBuilder("pdeanim-tests")
    v, f, owner = rig_geometry(rig)
    joints = np.zeros((len(v), 4), np.uint8)
    joints[:, 0] = owner
    weights = np.zeros((len(v), 4), np.float32)
    weights[:, 0] = 1.0
    attrs = {"POSITION": b.add_accessor(v.astype(np.float32), target=ARRAY_BUFFER, minmax=True),
             "JOINTS_0": b.add_accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.add_accessor(weights, target=ARRAY_BUFFER)}
    idx = b.add_accessor(f.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
    n = len(rig.joints)
    ibm = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    ibm[:, :3, 3] = -rig.positions()
    ibm_acc = b.add_accessor(ibm.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32), acc_type="MAT4")
    nodes = [{"name": name, "translation": list(t)} for name, _, t in rig.joints]
    for j, (_, parent, _) in enumerate(rig.joints):
        if parent >= 0:
            nodes[parent].setdefault("children", []).append(j)
    roots = [j for j, (_, parent, _) in enumerate(rig.joints) if parent < 0]
    nodes.append({"name": "body", "mesh": 0, "skin": 0})
    b.doc.update({"scene": 0, "scenes": [{"nodes": [*roots, n]}], "nodes": nodes,
                  "meshes": [{"primitives": [{"attributes": attrs, "indices": idx}]}],
                  "skins": [{"joints": list(range(n)), "inverseBindMatrices": ibm_acc}]})
    return b.to_glb()
