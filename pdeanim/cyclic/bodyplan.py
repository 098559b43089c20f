"""The body a gait moves: its legs, the joint that carries them all (the root the bob and pitch move), the
pivot (the hind girdle), and the axial chains that counter-move: the spine between the hind and front
girdles (or, on two legs, the torso up to its last branching joint), the neck out to the head, the tail."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from .feet import control_moves
from .legs import Axes, Leg, find_legs
from .skeleton import Skeleton


@dataclass(frozen=True)
class BodyPlan:
    """Skeleton, axes and legs, with root (the joint every leg hangs under), pivot (the hind girdle), the
    girdle of each row (front first), spine and neck and tail joints (each ordered outward), and the
    reference leg length (mean over the legs) the gait's sizes scale with."""

    skeleton: Skeleton
    axes: Axes
    legs: tuple[Leg, ...]
    root: int
    pivot: int
    girdles: tuple[int, ...]
    spine: tuple[int, ...]
    neck: tuple[int, ...]
    tail: tuple[int, ...]
    followers: tuple[tuple[int, int], ...] = ()

    @property
    def rows(self) -> int:
        """Number of leg rows (1 on two legs, 2 on four, ...)."""
        return len(self.girdles)

    @property
    def leg_length(self) -> float:
        """Mean IK length of the legs."""
        return float(np.mean([leg.length for leg in self.legs]))

    def describe(self) -> dict[str, Any]:
        """JSON-able summary: each leg's name, foot, joints and IK bones, and the axial chains."""
        n = self.skeleton.names
        return {
            "legs": [{"name": leg.name, "foot": n[leg.foot], "joints": [n[j] for j in leg.chain],
                      "ik_bones": len(leg.ik) - 1, "row": leg.row, "side": leg.side} for leg in self.legs],
            "root": n[self.root], "spine": [n[j] for j in self.spine], "neck": [n[j] for j in self.neck],
            "tail": [n[j] for j in self.tail], "forward": self.axes.forward.tolist(),
            "leg_length": self.leg_length,
            "followers": [{"joint": n[c], "follows": n[p]} for c, p in self.followers],
        }


def _outward(sk: Skeleton, start: int, exclude: np.ndarray, score: np.ndarray) -> tuple[int, ...]:
    """The chain from a child of start (not under a joint masked in exclude) down to the leaf with the
    highest score; empty when start has no such child."""
    kids = [c for c in sk.children[start] if not exclude[c]]
    if not kids:
        return ()
    leaf_of = {c: sk.deepest_leaf(c, score) for c in kids}
    best = max(kids, key=lambda c: score[leaf_of[c]])
    return tuple(sk.path_down(best, leaf_of[best]))


def _row_girdle(sk: Skeleton, legs: list[Leg], row: int) -> int:
    return sk.common_ancestor([leg.girdle for leg in legs if leg.row == row])


def _torso(sk: Skeleton, girdle: int, leg_mask: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """On one row of legs: the torso chain up to the highest leaf, split into spine (up to its last
    branching joint) and neck (after it)."""
    chain = _outward(sk, girdle, leg_mask, sk.positions[:, 1])
    branch = [i for i, j in enumerate(chain[:-1]) if len(sk.children[j]) > 1]
    cut = branch[-1] + 1 if branch else len(chain) // 2
    return chain[:cut], chain[cut:]


def body_plan(sk: Skeleton, legs: list[str] | None = None, forward: object = None,
              root: int | str | None = None) -> BodyPlan:
    """Find legs and axial chains; ``root`` overrides the joint the body motion moves (it must carry every
    leg). Control bones carrying foot vertices outside the legs are hung under the leg joint they sit at
    first (:func:`.feet.control_moves`). Raises InputError when no leg is found or the root does not carry
    them."""
    moves = control_moves(sk)
    sk = sk.reparented(moves)
    found, axes = find_legs(sk, legs, forward)
    rows = max(leg.row for leg in found) + 1
    girdles = tuple(_row_girdle(sk, found, r) for r in range(rows))
    carrier = sk.common_ancestor(list(girdles))
    if root is not None:
        r = sk.index(root)
        if any(not sk.subtrees[r, leg.chain[0]] or r in leg.chain for leg in found):
            raise InputError(f"the body joint {sk.names[r]!r} must be an ancestor of every leg "
                             f"({', '.join(sk.names[leg.foot] for leg in found)})")
        carrier = r
    leg_mask = np.zeros(sk.n, bool)
    for leg in found:
        leg_mask |= sk.subtrees[leg.chain[0]]
    fwd = sk.positions @ axes.forward
    pivot = girdles[-1]
    if rows > 1:
        front = girdles[0]
        top = sk.common_ancestor([pivot, front])
        spine = tuple(sk.path_down(top, front)[1:])
        axial = np.zeros(sk.n, bool)
        axial[list(spine)] = True
        neck = _outward(sk, front, leg_mask | axial, fwd)
        tail = _outward(sk, pivot, leg_mask | axial | _under(sk, spine), -fwd)
    else:
        spine, neck = _torso(sk, pivot, leg_mask)
        tail = ()
    return BodyPlan(sk, axes, tuple(found), carrier, pivot, girdles, spine, neck, tail,
                    tuple(sorted(moves.items())))


def _under(sk: Skeleton, joints: tuple[int, ...]) -> np.ndarray:
    mask = np.zeros(sk.n, bool)
    for j in joints:
        mask |= sk.subtrees[j]
    return mask


def plan_of(skinned: Any, legs: list[str] | None = None, forward: object = None,
            root: int | str | None = None) -> BodyPlan:
    """The body plan of a :class:`pdeanim.gltf.skin.SkinnedMesh` at rest."""
    return body_plan(Skeleton.of(skinned), legs, forward, root)
