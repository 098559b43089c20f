"""A skeleton at rest: joint names, the joint tree and world matrices, with the tree queries the gait code
needs (children, leaves, paths, subtrees, lowest common ancestors) and the ground height under it."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from ..errors import InputError, MeshInputError

UP = np.array([0.0, 1.0, 0.0])
"""glTF's up axis: the ground plane is y = ground."""
CONTACT = 0.02
"""Mesh vertices within this share of the mesh's height of the ground at rest touch the ground."""


@dataclass(frozen=True)
class Skeleton:
    """names (J,), parents (J,) int (-1 for roots), rest (J, 4, 4) world matrices at rest, ground: the height
    of the lowest point of the skinned mesh at rest (or of the lowest joint); contact (J,): how many mesh
    vertices touching the ground at rest each joint moves most (its largest skin weight); tall: the mesh's
    height above the ground at rest (0 without a mesh); contact_at (J,): those vertices' rest positions
    (m_j, 3) per joint."""

    names: tuple[str, ...]
    parents: np.ndarray
    rest: np.ndarray
    ground: float
    contact: np.ndarray | None = None
    tall: float = 0.0
    contact_at: tuple[np.ndarray, ...] | None = None

    @staticmethod
    def of(skinned: Any) -> Skeleton:
        """The skeleton of a :class:`pdeanim.gltf.skin.SkinnedMesh` at its rest pose."""
        from ..gltf.skin import joint_world_matrices, skin_vertices

        rest = joint_world_matrices(skinned)
        verts = skin_vertices(skinned, rest)
        lowest = float(rest[:, 1, 3].min())
        ground = min(float(verts[:, 1].min()), lowest) if len(verts) else lowest
        tall = float(verts[:, 1].max() - ground) if len(verts) else 0.0
        contact = np.zeros(len(rest), np.int64)
        at = tuple(np.zeros((0, 3)) for _ in range(len(rest)))
        if len(verts) and skinned.vertex_joints.shape[1]:
            down = (verts[:, 1] <= ground + CONTACT * tall) & (skinned.vertex_weights.sum(axis=1) > 0)
            rows = np.flatnonzero(down)
            owner = skinned.vertex_joints[rows, np.argmax(skinned.vertex_weights[rows], axis=1)]
            contact = np.bincount(owner, minlength=len(rest))[: len(rest)]
            at = tuple(verts[rows[owner == j]] for j in range(len(rest)))
        return Skeleton(tuple(skinned.joint_names), np.asarray(skinned.joint_parents, np.int64), rest, ground,
                        contact, tall, at)

    def reparented(self, moves: dict[int, int]) -> Skeleton:
        """The same skeleton with joint j hung under joint moves[j] (world matrices unchanged): a control
        bone then follows the leg joint it belongs to."""
        if not moves:
            return self
        parents = self.parents.copy()
        for j, p in moves.items():
            parents[j] = p
        return Skeleton(self.names, parents, self.rest, self.ground, self.contact, self.tall, self.contact_at)

    @property
    def n(self) -> int:
        """Number of joints J."""
        return len(self.names)

    @cached_property
    def positions(self) -> np.ndarray:
        """(J, 3) joint positions at rest."""
        return self.rest[:, :3, 3]

    def height(self, j: int) -> float:
        """Height of joint j above the ground at rest."""
        return float(self.positions[j, 1] - self.ground)

    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        """Child joints of every joint."""
        out: list[list[int]] = [[] for _ in range(self.n)]
        for j, p in enumerate(self.parents):
            if p >= 0:
                out[int(p)].append(j)
        return tuple(tuple(c) for c in out)

    def leaves(self) -> list[int]:
        """Joints without child joints."""
        return [j for j in range(self.n) if not self.children[j]]

    def ancestors(self, j: int) -> list[int]:
        """Ancestors of joint j, nearest first."""
        out, p = [], int(self.parents[j])
        while p >= 0:
            out.append(p)
            p = int(self.parents[p])
        return out

    def path_down(self, top: int, bottom: int) -> list[int]:
        """Joints from top down to bottom, both included; InputError when top is not an ancestor of bottom."""
        chain = [bottom]
        for p in self.ancestors(bottom):
            if chain[-1] == top:
                break
            chain.append(p)
        if chain[-1] != top:
            raise InputError(f"joint {self.names[top]!r} is not an ancestor of {self.names[bottom]!r}")
        return chain[::-1]

    def common_ancestor(self, joints: list[int]) -> int:
        """The lowest joint that is (or is an ancestor of) every joint given; InputError when they lie in
        separate trees."""
        common = None
        for j in joints:
            line = [j, *self.ancestors(j)]
            common = line if common is None else [a for a in line if a in set(common)]
        if not common:
            raise InputError("the legs hang from separate joint trees: no joint carries them all")
        return common[0]

    @cached_property
    def subtrees(self) -> np.ndarray:
        """(J, J) bool: row j marks joint j and all its descendants."""
        mask = np.eye(self.n, dtype=bool)
        for j in range(self.n):
            for a in self.ancestors(j):
                mask[a, j] = True
        return mask

    def index(self, key: int | str) -> int:
        """Index of a joint given by index or name (MeshInputError naming the joints when there is none)."""
        if isinstance(key, str):
            if key not in self.names:
                raise MeshInputError(f"no joint named {key!r}; joints: {', '.join(self.names)}")
            return self.names.index(key)
        if not 0 <= int(key) < self.n:
            raise MeshInputError(f"joint index {key} out of range [0, {self.n})")
        return int(key)

    def deepest_leaf(self, j: int, score: np.ndarray) -> int:
        """The leaf under joint j (or j itself) with the largest score (J,)."""
        under = np.flatnonzero(self.subtrees[j])
        leaves = [k for k in under if not self.children[k]]
        return int(max(leaves, key=lambda k: score[k]))
