"""Find the legs of a skeleton: feet where the skinned mesh touches the ground at rest (:mod:`.feet`), each
leg the chain from below its girdle (the lowest joint that also carries another foot) down to its foot,
sorted into left and right by the skeleton's mirror symmetry and into rows from front to back along the
facing direction. ``--legs`` names the feet instead; with no leg found the error lists the candidate chains
seen and why each was rejected.

The foot is the effector the IK places (the ankle, the start of a paw); the IK bends the last two bones above
it, or the last three when they descend in a zigzag (a digitigrade hind leg).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, ParameterError
from .feet import Contact, ground_contacts
from .skeleton import UP, Skeleton

DESCENT = 0.5
"""A leg drops at least this share of its top height from its top joint to its leaf."""
MID_PLANE = 0.05
"""Feet closer to the mirror plane than this share of their leg length are on it (a tail, not a leg)."""
ZIGZAG_DEGREES = 5.0
"""Both bends of a three-bone leg must exceed this for three-bone IK (else the last two bones bend)."""


@dataclass(frozen=True)
class Axes:
    """Body axes at rest: up (glTF +y), forward (the facing direction) and left = up x forward, and the
    lateral coordinate of the mirror plane."""

    up: np.ndarray
    forward: np.ndarray
    left: np.ndarray
    mid: float


@dataclass(frozen=True)
class Leg:
    """One leg: chain (top .. foot joints), ik (the joints the IK moves, from its first bone's start to the
    foot), girdle (the joint the leg hangs from), side (+1 left, -1 right, 0 on the mirror plane), row (0 =
    front), length (summed IK bone lengths at rest), a name such as "hind-left", and toe: the ball joint
    of a plantigrade foot (heel and toes on the ground at rest; -1 otherwise), which rolls."""

    chain: tuple[int, ...]
    ik: tuple[int, ...]
    girdle: int
    side: int
    row: int
    length: float
    name: str
    toe: int = -1

    @property
    def foot(self) -> int:
        """The foot joint (the IK effector)."""
        return self.chain[-1]


def _mirror_score(pos: np.ndarray, axis: np.ndarray) -> tuple[float, float]:
    """Mean distance from each joint mirrored about the plane normal to axis (through the joints' mean) to
    its nearest joint, and the plane's coordinate along axis."""
    x = pos @ axis
    mid = float(x.mean())
    mirrored = pos - 2.0 * (x - mid)[:, None] * axis
    d = np.linalg.norm(mirrored[:, None] - pos[None], axis=2).min(axis=1)
    return float(d.mean()), mid


def _lateral(pos: np.ndarray) -> tuple[np.ndarray, float]:
    """The horizontal axis the joints are most mirror-symmetric about (world x wins ties) and the plane."""
    flat = pos - np.outer(pos @ UP, UP)
    cands = [np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])]
    cands += [np.array([np.cos(a), 0.0, np.sin(a)]) for a in np.radians(np.arange(5.0, 180.0, 5.0))]
    _, _, vt = np.linalg.svd(flat - flat.mean(axis=0), full_matrices=False)
    cands += [v / np.linalg.norm(v) for v in vt[:2] if np.linalg.norm(v) > 0.5]
    scores = [_mirror_score(pos, a) for a in cands]
    best = min(range(len(cands)), key=lambda i: scores[i][0])
    tie = 1e-9 * max(float(np.ptp(pos, axis=0).max()), 1e-300)
    if scores[0][0] <= scores[best][0] + tie:
        best = 0
    return cands[best], scores[best][1]


def _facing_sign(sk: Skeleton, forward: np.ndarray, leaves: list[int], toes: list[tuple[int, int]]) -> float:
    """+1 when forward points to the head: a joint named head/neck/skull (or away from a tail); else the
    highest leaf that is no foot when it sits clearly off-centre; else the way the toes point (the last bone
    of each leg); else glTF's +z front."""
    pos, centre = sk.positions, sk.positions.mean(axis=0)
    extent = float(np.ptp(pos, axis=0).max()) or 1.0  # the size of the skeleton
    for pattern, sign in ((r"head|neck|skull", 1.0), (r"tail", -1.0)):
        hits = [j for j, n in enumerate(sk.names) if re.search(pattern, n, re.IGNORECASE)]
        if hits:
            off = float((pos[hits].mean(axis=0) - centre) @ forward)
            if abs(off) > 0.05 * extent:
                return sign * np.sign(off)
    if leaves:
        top = max(leaves, key=lambda j: pos[j, 1])
        off = float((pos[top] - centre) @ forward)
        if abs(off) > 0.1 * extent:
            return float(np.sign(off))
    if toes:
        bones = np.array([pos[b] - pos[a] for a, b in toes])
        lean = float(np.mean(bones @ forward / np.maximum(np.linalg.norm(bones, axis=1), 1e-300)))
        if abs(lean) > 0.2:
            return float(np.sign(lean))
    return 1.0 if forward[2] >= 0 else -1.0


def body_axes(sk: Skeleton, other_leaves: list[int], toes: list[tuple[int, int]], forward: object = None
              ) -> Axes:
    """The body axes from the mirror symmetry of the joints (or a given forward direction); other_leaves
    (leaves that are no feet) and toes (each leg's last bone) tell which way is forward."""
    if forward is not None:
        f = np.asarray(forward, np.float64).reshape(-1)
        if f.shape != (3,) or not np.isfinite(f).all():
            raise ParameterError("forward must be three finite numbers")
        f = f - (f @ UP) * UP
        if np.linalg.norm(f) < 1e-9:
            raise ParameterError("forward must not point straight up or down")
        f = f / np.linalg.norm(f)
        left = np.cross(UP, f)
        return Axes(UP, f, left, float((sk.positions @ left).mean()))
    lat, mid = _lateral(sk.positions)
    f = np.cross(lat, UP)
    f = f * _facing_sign(sk, f, other_leaves, toes)
    left = np.cross(UP, f)
    return Axes(UP, f, left, mid if left @ lat > 0 else -mid)


def _bend(a: np.ndarray, b: np.ndarray) -> float:
    """Angle in degrees between two bone vectors."""
    c = a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def ik_joints(sk: Skeleton, chain: list[int]) -> tuple[int, ...]:
    """The joints the IK moves: the last three bones when they all descend and bend in a zigzag, else the
    last two (or the only one)."""
    p = sk.positions
    if len(chain) >= 4:
        b = [p[chain[-3 + i]] - p[chain[-4 + i]] for i in range(3)]
        zigzag = np.cross(b[0], b[1]) @ np.cross(b[1], b[2]) < 0
        descend = all(v @ UP < 0 for v in b)
        if zigzag and descend and min(_bend(b[0], b[1]), _bend(b[1], b[2])) > ZIGZAG_DEGREES:
            return tuple(chain[-4:])
    return tuple(chain[-3:]) if len(chain) >= 3 else tuple(chain[-2:])


def _girdle(sk: Skeleton, foot: int, feet: list[int]) -> int:
    """The joint a leg hangs from: the lowest ancestor of its foot that also carries another foot (with one
    foot: the first ancestor with several children), or the root."""
    others = [f for f in feet if f != foot]
    line = sk.ancestors(foot)
    for p in line:
        if any(sk.subtrees[p, f] for f in others) if others else len(sk.children[p]) > 1:
            return p
    return line[-1] if line else foot


def _toe(sk: Skeleton, foot: int) -> tuple[int, int]:
    """The bone that shows which way a foot points: from the foot to its farthest joint below, or the bone
    ending at the foot."""
    below = [j for j in np.flatnonzero(sk.subtrees[foot]) if j != foot]
    if below:
        p = sk.positions
        return foot, int(max(below, key=lambda j: float(np.linalg.norm(p[j] - p[foot]))))
    return int(sk.parents[foot]), foot


def _make_leg(sk: Skeleton, girdle: int, chain: list[int], axes: Axes) -> tuple[Leg, float]:
    """A leg (row and name filled in later) and the forward coordinate of its top joint."""
    ik = ik_joints(sk, chain)
    p = sk.positions
    length = float(sum(np.linalg.norm(p[b] - p[a]) for a, b in zip(ik[:-1], ik[1:], strict=True)))
    lateral = float(p[chain[-1]] @ axes.left) - axes.mid
    side = 0 if abs(lateral) < MID_PLANE * max(length, 1e-300) else int(np.sign(lateral))
    return Leg(tuple(chain), ik, girdle, side, 0, length, ""), float(p[chain[0]] @ axes.forward)


def _rows(legs: list[tuple[Leg, float]]) -> list[Leg]:
    """Rows from front to back: the k-th left leg pairs with the k-th right leg (by their forward
    coordinate) when the sides have as many legs, else every leg is a row of its own."""
    lefts = sorted([x for x in legs if x[0].side > 0], key=lambda x: -x[1])
    rights = sorted([x for x in legs if x[0].side < 0], key=lambda x: -x[1])
    middle = [x for x in legs if x[0].side == 0]
    if len(lefts) == len(rights) and not middle:
        rows = [[a[0], b[0]] for a, b in zip(lefts, rights, strict=True)]
    else:
        rows = [[x[0]] for x in sorted(legs, key=lambda x: -x[1])]
    labels = {1: [""], 2: ["front", "hind"], 3: ["front", "middle", "hind"]}.get(
        len(rows), [f"row{k + 1}" for k in range(len(rows))])
    out = []
    for k, row in enumerate(rows):
        for leg in row:
            side = {1: "left", -1: "right", 0: "middle"}[leg.side]
            name = f"{labels[k]}-{side}" if labels[k] else side
            out.append(Leg(leg.chain, leg.ik, leg.girdle, leg.side, k, leg.length, name, leg.toe))
    return out


def _joint_spec(sk: Skeleton, spec: str) -> tuple[int | None, int]:
    """(top or None, foot) of a leg named "FOOT" or "TOP:FOOT" (joint names may hold colons themselves,
    like "mixamorig:LeftFoot": a whole name wins over a split)."""
    spec = spec.strip()
    if spec in sk.names:
        return None, sk.names.index(spec)
    for i in [i for i, ch in enumerate(spec) if ch == ":"]:
        top, foot = spec[:i].strip(), spec[i + 1:].strip()
        if top in sk.names and foot in sk.names:
            return sk.names.index(top), sk.names.index(foot)
    top_name, _, foot_name = spec.rpartition(":")
    foot = sk.index(foot_name.strip())
    return (sk.index(top_name.strip()) if top_name.strip() else None), foot


def _named_chains(sk: Skeleton, specs: list[str]) -> list[list[int]]:
    """The chains (girdle first) of legs named "FOOT" or "TOP:FOOT"."""
    named = [_joint_spec(sk, s) for s in specs]
    feet = [f for _, f in named]
    chains = []
    for (top, foot), spec in zip(named, specs, strict=True):
        if top is not None:
            if sk.parents[top] < 0:
                raise InputError(f"leg top {sk.names[top]!r} is a root joint: name the joint below the body")
            chains.append([int(sk.parents[top]), *sk.path_down(top, foot)])
            continue
        if sk.parents[foot] < 0:
            raise InputError(f"foot {spec.strip()!r} has no parent joint to bend")
        chains.append(sk.path_down(_girdle(sk, foot, feet), foot))
    return chains


def _reasons(sk: Skeleton, rejected: list[tuple[str, str]]) -> str:
    if not rejected:
        return f"no mesh vertex on the ground (y = {sk.ground:.4g}) at rest has a skin weight on a joint"
    return "; ".join(f"{what}: {why}" for what, why in rejected)


def find_legs(sk: Skeleton, legs: list[str] | None = None, forward: object = None) -> tuple[list[Leg], Axes]:
    """The legs (front row first, left before right) and the body axes. A foot is the joint where a leg
    meets its ground contact at rest (:mod:`.feet`); ``legs`` names the feet ("FOOT" or "TOP:FOOT") instead.
    Raises InputError listing the candidate chains seen and why each was rejected when none is a leg."""
    rejected: list[tuple[str, str]] = []
    if legs:
        chains = _named_chains(sk, legs)
    else:
        contacts = ground_contacts(sk)
        for c in contacts:
            if c.reason:
                rejected.append((_contact_name(sk, c), c.reason))
        feet = [c.foot for c in contacts if not c.reason]
        chains = []
        for foot in feet:
            chain = sk.path_down(_girdle(sk, foot, feet), foot)
            why = _chain_problem(sk, chain)
            if why:
                rejected.append((_chain_name(sk, chain), why))
            else:
                chains.append(chain)
        kept = [c[-1] for c in chains]
        chains = [sk.path_down(_girdle(sk, c[-1], kept), c[-1]) for c in chains]
    toes = [_toe(sk, c[-1]) for c in chains]
    in_feet = np.zeros(sk.n, bool)
    for c in chains:
        in_feet |= sk.subtrees[c[-1]]
    others = [j for j in sk.leaves() if not in_feet[j]]
    axes = body_axes(sk, others, toes, forward)
    made = [_make_leg(sk, c[0], c[1:], axes) for c in chains]
    if not legs:
        for m, c in zip(made, chains, strict=True):
            if m[0].side == 0:
                rejected.append((_chain_name(sk, c), f"its foot lies within {MID_PLANE:.0%} of its leg's "
                                 "length of the body's mirror plane (a tail or a body part, not a leg)"))
        made = [m for m in made if m[0].side != 0]
        if len(made) != len(chains):  # girdles again without the legs dropped
            kept = [m[0].foot for m in made]
            made = [_make_leg(sk, g, sk.path_down(g, f)[1:], axes)
                    for g, f in ((_girdle(sk, f, kept), f) for f in kept)]
    if not legs:
        toe_of = {c.foot: c.toe for c in contacts if not c.reason}
        made = [(replace(m[0], toe=toe_of.get(m[0].foot, -1)), m[1]) for m in made]
    if not made:
        raise InputError(
            f"no legs found (ground at y = {sk.ground:.4g}); candidate chains seen and why each is no leg: "
            + _reasons(sk, rejected) + "; joints seen, with their height: "
            + ", ".join(f"{n} {sk.height(j):.3g}" for j, n in enumerate(sk.names))
            + "; name the feet with --legs FOOT,FOOT,... (or TOP:FOOT)")
    dup = {m[0].foot for m in made}
    if len(dup) != len(made):
        raise InputError("a foot joint is named twice in legs")
    return _rows(made), axes


def _contact_name(sk: Skeleton, c: Contact) -> str:
    joints = ", ".join(sk.names[j] for j in c.joints[:4]) + (" ..." if len(c.joints) > 4 else "")
    return f"ground contact of {joints} ({c.vertices} vertices)"


def _chain_name(sk: Skeleton, chain: list[int]) -> str:
    return " > ".join(sk.names[j] for j in chain)


def _chain_problem(sk: Skeleton, chain: list[int]) -> str:
    """Why a chain (girdle first) is no leg, or "" when it is one."""
    if len(chain) < 3:
        return "no bone between its foot and the joint it hangs from to bend"
    top_h, foot_h = sk.height(chain[1]), sk.height(chain[-1])
    if top_h <= 0 or top_h - foot_h < DESCENT * top_h:
        return (f"it drops {top_h - foot_h:.3g} from its top joint at height {top_h:.3g}, under "
                f"{DESCENT:.0%} of that height")
    return ""
