"""Where legs meet the ground, found from the skinned mesh: the vertices touching the ground at rest and the
joints that move them (:attr:`Skeleton.contact`). A foot is the joint where a leg meets its ground contact
(the ankle, the start of a paw): the joint carrying every joint that moves a good share of one foot's
contact vertices (heel and toes, the digits of a paw) and stands low in its leg, whatever the slope of
the bones below it.

Bones that carry foot vertices but hang outside the legs (an IK target or control bone parented to the
armature root; glTF keeps no IK constraint) are hung under the leg joint they sit at, so the leg solver
drives them with the leg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skeleton import Skeleton

LEG_DROP = 0.25
"""A joint is on a leg when one of its ancestors stands this share of the mesh's height above it."""
FOLLOW = 0.5
"""A control bone follows the nearest leg joint within this share of the mesh's height of it."""
FOOT_SHARE = 0.2
"""A joint counts for a foot when it moves at least this share of the foot's contact vertices."""
FOOT_LOW = 0.2
"""... and stands at most this share of its highest ancestor's height above the ground (the far end of a
steep shank touching the ground does not make the shank part of the foot)."""
TOE_LOW = 0.3
"""Contact joints whose common ancestor on a leg is under this share of the mesh's height are one foot."""


@dataclass(frozen=True)
class Contact:
    """A ground contact seen at rest: its foot joint (or -1), the contact joints it groups, its vertex
    count, why it is no foot ("" when it is one) and its toe: the highest joint below the foot that also
    carries a good share of the contact (the ball of a plantigrade foot; -1 when there is none)."""

    foot: int
    joints: tuple[int, ...]
    vertices: int
    reason: str = ""
    toe: int = -1


def _tall(sk: Skeleton) -> float:
    """The height the thresholds scale with: the mesh's, else the skeleton's."""
    return sk.tall if sk.tall > 0 else max(float(np.ptp(sk.positions[:, 1])), 1e-300)


def on_leg(sk: Skeleton) -> np.ndarray:
    """(J,) bool: joints with an ancestor at least LEG_DROP of the mesh's height above them."""
    h = sk.positions[:, 1]
    return np.array([bool(anc) and h[anc].max() - h[j] >= LEG_DROP * _tall(sk)
                     for j, anc in ((j, sk.ancestors(j)) for j in range(sk.n))])


def control_moves(sk: Skeleton) -> dict[int, int]:
    """Joints carrying ground contact outside every leg (control bones), each mapped to the leg joint it is
    to hang under: the nearest joint on a leg within FOLLOW of the mesh's height, or a control bone nearer
    that already hangs under the same leg joint (a toe control under its foot control)."""
    if sk.contact is None:
        return {}
    leg = on_leg(sk)
    contact = np.asarray(sk.contact) > 0
    sub = sk.subtrees
    tops = []
    for c in np.flatnonzero(contact & ~leg):
        top = int(c)
        while sk.parents[top] >= 0:
            p = int(sk.parents[top])
            others = sub[p] & ~sub[top]
            if (others & (leg | contact)).any():
                break
            top = p
        if sk.parents[top] >= 0 and top not in tops:
            tops.append(top)
    pos, reach = sk.positions, FOLLOW * _tall(sk)
    by_leg: dict[int, list[tuple[float, int]]] = {}
    for top in tops:
        free = leg & ~sub[top]
        free[sk.ancestors(top)] = False
        cand = np.flatnonzero(free)
        if not len(cand):
            continue
        d = np.linalg.norm(pos[cand] - pos[top], axis=1)
        i = int(np.argmin(d))
        if d[i] <= reach:
            by_leg.setdefault(int(cand[i]), []).append((float(d[i]), top))
    moves: dict[int, int] = {}
    for host, controls in by_leg.items():  # nearest first; later ones may hang under earlier ones
        hung = [host]
        for _, top in sorted(controls):
            moves[top] = min(hung, key=lambda h: float(np.linalg.norm(pos[h] - pos[top])))
            hung.append(top)
    return moves


def ground_contacts(sk: Skeleton) -> list[Contact]:
    """The ground contacts at rest (after control bones were hung under their legs): contact joints grouped
    by foot, each with its foot joint or the reason it is none."""
    if sk.contact is None or not np.any(sk.contact):
        return []
    count = np.asarray(sk.contact)
    joints = [int(j) for j in np.flatnonzero(count > 0)]
    leg = on_leg(sk)
    low = TOE_LOW * _tall(sk)
    group = {j: j for j in joints}

    def find(j: int) -> int:
        while group[j] != j:
            j = group[j]
        return j

    for i, a in enumerate(joints):
        for b in joints[i + 1:]:
            lca = sk.common_ancestor([a, b]) if _same_tree(sk, a, b) else -1
            if lca >= 0 and leg[lca] and sk.height(lca) < low:
                group[find(b)] = find(a)
    out = []
    for root in sorted({find(j) for j in joints}):
        members = tuple(j for j in joints if find(j) == root)
        total = int(count[list(members)].sum())
        strong = [j for j in members if count[j] >= FOOT_SHARE * total and _low(sk, j)]
        foot = sk.common_ancestor(strong) if strong else min(members, key=sk.height)
        reason = "" if leg[foot] else (
            f"no joint above it stands {LEG_DROP:.0%} of the mesh's height higher (a body, tail or control "
            "bone lying on the ground, not a leg)")
        if not strong and not reason:
            reason = (f"the joints moving it stand above {FOOT_LOW:.0%} of their leg's height (the far end "
                      "of a shank, not a foot)")
        toes = [j for j in strong if j != foot]
        toe = min(toes, key=lambda j: len(sk.ancestors(j))) if toes else -1
        out.append(Contact(foot, members, total, reason, toe))
    return out


def _low(sk: Skeleton, j: int) -> bool:
    """Whether joint j stands low in its leg (at most FOOT_LOW of its highest ancestor's height)."""
    anc = sk.ancestors(j)
    return not anc or sk.height(j) <= FOOT_LOW * max(sk.height(a) for a in anc)


def _same_tree(sk: Skeleton, a: int, b: int) -> bool:
    return bool(set([a, *sk.ancestors(a)]) & set([b, *sk.ancestors(b)]))
