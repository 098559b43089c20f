"""Skinned test rigs built in code: a biped (hip, two three-joint legs), a quadruped (two-bone front legs,
three-bone digitigrade hind legs, spine, neck, head, tail) and a hexapod (three thorax segments, six two-bone
legs, head, abdomen). Each bone is a box bound rigidly to its joint; every foot has a flat pad bound to the
foot joint whose underside lies on the ground (y = 0)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder

PAD = 0.03
"""Half height of a foot pad: foot joints sit this high above the ground."""


@dataclass(frozen=True)
class Rig:
    """joints: (name, parent index, local translation) with y up and z forward; feet: the joints with a pad
    under them (and whose incoming bone stops short of the pad); body: (joint, half size) boxes; pads:
    (joint the pad is bound to, joint it lies under) instead of the feet's own; controls: joints that get no
    bone box from their parent (IK control and pole bones, the first joint above a root on the ground);
    bones: extra bone boxes (joint bound to, from joint, to joint); bind_turn: degrees each joint's bind
    pose is turned from its node pose (the mesh is stored in bind space, so the node pose differs from the
    bind pose)."""

    joints: list[tuple[str, int, tuple[float, float, float]]]
    feet: tuple[str, ...]
    body: tuple[tuple[str, float], ...] = ()
    pads: tuple[tuple[str, str], ...] = ()
    controls: tuple[str, ...] = ()
    bones: tuple[tuple[str, str, str], ...] = ()
    bind_turn: float = 0.0

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
        return replace(self, joints=[(n, p, tuple(rot @ np.asarray(t))) for n, p, t in self.joints])

    def renamed(self) -> Rig:
        """The same rig with neutral joint names j0, j1, ... (legs must be found from the shape alone)."""
        names = {n: f"j{i}" for i, (n, _, _) in enumerate(self.joints)}
        return replace(self, joints=[(names[n], p, t) for n, p, t in self.joints],
                       feet=tuple(names[f] for f in self.feet),
                       body=tuple((names[n], h) for n, h in self.body),
                       pads=tuple((names[a], names[b]) for a, b in self.pads),
                       controls=tuple(names[c] for c in self.controls),
                       bones=tuple(tuple(names[x] for x in b) for b in self.bones))


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


def _sloped() -> Rig:
    """A quadruped with Blender-style names whose paws slope steeply down-forward from the wrist and the
    start of the hind paw to the toe tips (the toe tip is a leaf; the pad under it is bound to the paw's
    start), digitigrade hind legs, and a bind pose that differs from the node pose."""
    axial = [("Bone", -1, (0.0, 1.0, -0.5)), ("Bone.001", 0, (0.0, 0.02, 0.5)),
             ("Bone.002", 1, (0.0, 0.0, 0.5)), ("Bone.003", 2, (0.0, 0.15, 0.15)),
             ("Bone.004", 3, (0.0, 0.12, 0.2)), ("Bone.005", 0, (0.0, 0.05, -0.2)),
             ("Bone.006", 5, (0.0, 0.04, -0.25))]
    hind = [("thigh", (0.15, -0.05, 0.0)), ("shin", (0.0, -0.35, 0.12)), ("hock", (0.0, -0.3, -0.15)),
            ("paw", (0.0, -0.2, 0.05)), ("toe", (0.0, -0.07, 0.07))]
    front = [("upper_arm", (0.15, -0.07, 0.0)), ("forearm", (0.0, -0.4, -0.05)), ("hand", (0.0, -0.4, 0.03)),
             ("finger", (0.0, -0.12, 0.08))]
    joints = list(axial)
    for side, sign in (("L", 1.0), ("R", -1.0)):
        for parent, leg in ((0, hind), (2, front)):
            for i, (name, (x, y, z)) in enumerate(leg):
                joints.append((f"{name}.{side}", parent if i == 0 else len(joints) - 1, (sign * x, y, z)))
    pads = tuple((f"{a}.{s}", f"{b}.{s}") for s in "LR" for a, b in (("paw", "toe"), ("hand", "finger")))
    return Rig(joints, (), (("Bone", 0.12), ("Bone.001", 0.12), ("Bone.002", 0.12), ("Bone.003", 0.06),
                            ("Bone.005", 0.04)), pads=pads, bind_turn=20.0)


def _controlled() -> Rig:
    """A quadruped exported the common Blender way: legs of two deform bones ending at the knee and elbow
    joints (no joint at the ankle), each paw bound to an IK control bone parented to the armature root
    (with a leaf at the toe), pole bones at the root carrying nothing, the root on the ground."""
    joints = [("root", -1, (0.0, 0.0, 0.0)), ("hips", 0, (0.0, 1.0, -0.5)), ("spine", 1, (0.0, 0.02, 0.5)),
              ("chest", 2, (0.0, 0.0, 0.5)), ("neck", 3, (0.0, 0.15, 0.15)), ("head", 4, (0.0, 0.12, 0.2))]
    bones, controls, pads = [], [], []
    for side, sign in (("L", 1.0), ("R", -1.0)):
        for upper, lower, ik, girdle, z, bend in (("thigh", "shin", "IK-foot", 1, -0.5, 0.06),
                                                  ("upper_arm", "forearm", "IK-hand", 3, 0.5, -0.06)):
            top = len(joints)
            joints += [(f"{upper}.{side}", girdle, (sign * 0.15, -0.05, 0.0)),
                       (f"{lower}.{side}", top, (0.0, -0.45, bend)),
                       (f"{ik}.{side}", 0, (sign * 0.15, 0.09, z)),
                       (f"{ik}.{side}_end", top + 2, (0.0, -0.06, 0.08)),
                       (f"pole.{lower}.{side}", 0, (sign * 0.15, 0.5, z + 0.6 * np.sign(bend)))]
            bones.append((f"{lower}.{side}", f"{lower}.{side}", f"{ik}.{side}"))
            controls += [f"{ik}.{side}", f"pole.{lower}.{side}"]
            pads.append((f"{ik}.{side}", f"{ik}.{side}_end"))
    return Rig(joints, (), (("hips", 0.12), ("spine", 0.12), ("chest", 0.12), ("neck", 0.06)),
               pads=tuple(pads), controls=("hips", *controls), bones=tuple(bones))


def _plantigrade() -> Rig:
    """A biped with Mixamo-style names (a colon in each) on plantigrade feet: a foot bone from the ankle
    down to the ball and a toe bone along the ground, a heel pad bound to the foot, and a bind pose that
    differs from the node pose."""
    joints = [("mixamorig:Hips", -1, (0.0, 1.0, 0.0)), ("mixamorig:Spine", 0, (0.0, 0.25, 0.0)),
              ("mixamorig:Head", 1, (0.0, 0.3, 0.02))]
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        top = len(joints)
        joints += [(f"mixamorig:{side}UpLeg", 0, (sign * 0.12, -0.05, 0.0)),
                   (f"mixamorig:{side}Leg", top, (0.0, -0.43, 0.03)),
                   (f"mixamorig:{side}Foot", top + 1, (0.0, -0.43, -0.03)),
                   (f"mixamorig:{side}ToeBase", top + 2, (0.0, -0.06, 0.13)),
                   (f"mixamorig:{side}Toe_End", top + 3, (0.0, 0.0, 0.06))]
    feet = ("mixamorig:LeftFoot", "mixamorig:RightFoot")
    return Rig(joints, feet, (("mixamorig:Hips", 0.1), ("mixamorig:Spine", 0.1)), bind_turn=15.0)


QUADRUPED = _quadruped()
HEXAPOD = _hexapod()
SLOPED = _sloped()
CONTROLLED = _controlled()
PLANTIGRADE = _plantigrade()
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
    controls = {rig.index(c) for c in rig.controls}
    boxes = []
    for j, (_, parent, _) in enumerate(rig.joints):
        if parent >= 0 and j not in controls:  # a bone into a foot stops short: only its pad is on the ground
            end = pos[parent] + 0.8 * (pos[j] - pos[parent]) if j in feet else pos[j]
            boxes.append((parent, pos[parent], end, 0.03))
    for owner, a, b in rig.bones:
        boxes.append((rig.index(owner), pos[rig.index(a)], pos[rig.index(b)], 0.03))
    for name, half in rig.body:
        j = rig.index(name)
        boxes.append((j, pos[j] + [0, 0, -half], pos[j] + [0, 0, half], half))
    pads = [(rig.index(a), rig.index(b)) for a, b in rig.pads] or [(j, j) for j in sorted(feet)]
    for j, at in pads:
        under = np.array([pos[at][0], PAD, pos[at][2]])
        boxes.append((j, under + [0, 0, -0.03], under + [0, 0, 0.08], PAD))
    verts, faces, owner = [], [], []
    for joint, a, b, half in boxes:
        v, f = _box(np.asarray(a, float), np.asarray(b, float), half)
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v)
        owner.append(np.full(len(v), joint))
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(owner)


def _bind_pose(rig: Rig) -> np.ndarray:
    """(J, 4, 4) bind-pose world matrices: at each joint, turned by bind_turn times 1, 2, 3 (cycling) degrees
    about a slanted axis (identity turns when bind_turn is 0)."""
    pos = rig.positions()
    out = np.broadcast_to(np.eye(4), (len(pos), 4, 4)).copy()
    axis = np.array([1.0, 1.0, 0.5]) / 1.5
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    for j in range(len(pos)):
        a = np.radians(rig.bind_turn * (1 + j % 3))
        out[j, :3, :3] = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)
        out[j, :3, 3] = pos[j]
    return out


def _bind_space(rig: Rig, verts: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Vertices (V, 3) placed at rest (node pose) moved into bind space: B_owner inv(N_owner) v."""
    bind, pos = _bind_pose(rig), rig.positions()
    return np.einsum("vij,vj->vi", bind[owner, :3, :3], verts - pos[owner]) + bind[owner, :3, 3]


def rig_glb(rig: Rig = BIPED) -> bytes:
    """The rig as a skinned GLB (one mesh node, one skin over every joint)."""
    b = GlbBuilder("pdeanim-tests")
    v, f, owner = rig_geometry(rig)
    joints = np.zeros((len(v), 4), np.uint8)
    joints[:, 0] = owner
    weights = np.zeros((len(v), 4), np.float32)
    weights[:, 0] = 1.0
    v = _bind_space(rig, v, owner)
    attrs = {"POSITION": b.add_accessor(v.astype(np.float32), target=ARRAY_BUFFER, minmax=True),
             "JOINTS_0": b.add_accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.add_accessor(weights, target=ARRAY_BUFFER)}
    idx = b.add_accessor(f.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
    n = len(rig.joints)
    ibm = np.linalg.inv(_bind_pose(rig))
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
