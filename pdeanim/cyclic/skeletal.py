"""Skeletal walk and run cycles: periodic expressions on the foot joints and the hip of a skinned mesh.

With T_y = sin(2 pi f t) and T_z = cos(2 pi f t) the feet follow (y up, z forward, x sideways)
    right: y = T_y (H + H_R) + H_RF,   z = -T_z (L + L_R)
    left:  y = T_y (H + H_L) + H_LF,   z = +T_z (L + L_L)
relative to their rest positions (``literal=True``). By default each foot is lifted only while it swings
forward (T_y is replaced by max(T_y, 0) for the right foot and max(-T_y, 0) for the left), so the stance foot
stays on the ground. The hip bobs by bob sin^2(2 pi f t), sways sideways by sway sin(2 pi f t) and is lowered
where a straight leg could not reach its foot target (a long stride needs bent knees). Each leg
reaches its foot target with analytic two-bone IK (or an aim for one-bone legs) applied to world matrices,
and the feet keep their rest orientation; the mesh follows by linear blend skinning. Every cycle repeats with
period 1 / f.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from ..errors import InputError, ParameterError
from ..poses import Poses, make_poses

GAITS: dict[str, dict[str, float]] = {
    "walk": {"step_height": 0.12, "step_length": 0.3, "frequency": 1.0, "hip_bob": 0.03},
    "run": {"step_height": 0.3, "step_length": 0.55, "frequency": 1.6, "hip_bob": 0.07},
}
"""Gait presets; heights and lengths are fractions of the leg length (hip to foot at rest)."""


@dataclass(frozen=True)
class StepParams:
    """Walk/run cycle parameters: H step_height, L step_length (fractions of the leg length), frequency f
    (cycles per second), the per-side fine tuning H_R, H_L, H_RF, H_LF, L_R, L_L (fractions of the leg
    length, default 0), hip_bob and hip_sway (fractions of the leg length), literal (Eq. 10 as printed)."""

    gait: str = "walk"
    step_height: float = 0.12
    step_length: float = 0.3
    frequency: float = 1.0
    height_right: float = 0.0
    height_left: float = 0.0
    lift_right: float = 0.0
    lift_left: float = 0.0
    length_right: float = 0.0
    length_left: float = 0.0
    hip_bob: float = 0.03
    hip_sway: float = 0.0
    literal: bool = False

    @staticmethod
    def preset(gait: str, **overrides: Any) -> StepParams:
        """The walk or run preset with overrides; raises ParameterError on unknown names or bad values."""
        if gait not in GAITS:
            raise ParameterError(f"unknown gait {gait!r} (known: {', '.join(GAITS)})")
        names = {f.name for f in fields(StepParams)}
        unknown = set(overrides) - names
        if unknown:
            raise ParameterError(f"unknown step parameter(s): {', '.join(sorted(unknown))}")
        try:
            vals = {
                k: (bool(v) if k == "literal" else float(v)) for k, v in {**GAITS[gait], **overrides}.items()
            }
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"bad step parameter value: {exc}") from exc
        p = replace(StepParams(), gait=gait, **vals)
        nums = [getattr(p, f.name) for f in fields(p) if f.name not in ("gait", "literal")]
        if not np.isfinite(nums).all() or p.frequency <= 0:
            raise ParameterError("step parameters must be finite and the frequency > 0")
        return p

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict of the parameters."""
        return asdict(self)


def foot_and_hip_offsets(
    p: StepParams, t: np.ndarray, leg: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World offsets (K, 3) from the rest pose of the right foot, left foot and hip at times t (K,)
    seconds."""
    w = 2 * np.pi * p.frequency * np.asarray(t, dtype=np.float64).reshape(-1)
    ty, tz = np.sin(w), np.cos(w)
    lift_r, lift_l = (ty, ty) if p.literal else (np.maximum(ty, 0.0), np.maximum(-ty, 0.0))
    zero = np.zeros_like(w)
    right = np.stack([zero, lift_r * (p.step_height + p.height_right) + p.lift_right,
                      -tz * (p.step_length + p.length_right)], axis=1)
    left = np.stack([zero, lift_l * (p.step_height + p.height_left) + p.lift_left,
                     tz * (p.step_length + p.length_left)], axis=1)
    hip = np.stack([p.hip_sway * ty, p.hip_bob * ty**2, zero], axis=1)
    return right * leg, left * leg, hip * leg


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations (K, 3, 3) turning unit vectors a (K, 3) onto b (K, 3)."""
    v = np.cross(a, b)
    c = np.einsum("ki,ki->k", a, b)
    vx = np.zeros((len(a), 3, 3))
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx = vx - vx.transpose(0, 2, 1)
    return np.eye(3) + vx + vx @ vx / np.maximum(1.0 + c, 1e-12)[:, None, None]


def _turn_subtree(world: np.ndarray, sub: np.ndarray, rot: np.ndarray, centre: np.ndarray) -> None:
    """Rotate the joints in mask sub (J,) of world (K, J, 4, 4) by rot (K, 3, 3) about centre (K, 3)."""
    g = np.zeros((len(rot), 4, 4))
    g[:, :3, :3] = rot
    g[:, :3, 3] = centre - np.einsum("kij,kj->ki", rot, centre)
    g[:, 3, 3] = 1.0
    world[:, sub] = g[:, None] @ world[:, sub]


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-300)


def reach(world: np.ndarray, subtree: np.ndarray, chain: list[int], foot: int, target: np.ndarray) -> None:
    """Move a leg in place so the foot joint reaches target (K, 3): two-bone IK when chain holds the upper
    and knee joints (the knee bends the way it bends now), an aim for one joint, a shift for none."""
    pos = lambda j: world[:, j, :3, 3]  # noqa: E731
    if not chain:
        trans = world[..., :3, 3]  # (K, J, 3) view
        trans[:, subtree[foot]] += (target - pos(foot))[:, None]
        return
    if len(chain) == 1:
        j = chain[0]
        _turn_subtree(
            world, subtree[j], _rotation_between(_unit(pos(foot) - pos(j)), _unit(target - pos(j))), pos(j)
        )
        return
    upper, knee = chain[-2], chain[-1]
    u, k, f = pos(upper).copy(), pos(knee).copy(), pos(foot).copy()
    a, b = np.linalg.norm(k - u, axis=1), np.linalg.norm(f - k, axis=1)
    to = target - u
    d = np.clip(np.linalg.norm(to, axis=1), np.abs(a - b) + 1e-9 * (a + b), (a + b) * (1 - 1e-9))
    axis = _unit(to)
    line = _unit(f - u)  # the knee's bend direction off the current upper-foot line is kept
    pole = (k - u) - line * np.einsum("ki,ki->k", k - u, line)[:, None]
    pole = np.where(np.linalg.norm(pole, axis=1, keepdims=True) > 1e-9 * a[:, None], pole, [0.0, 0.0, 1.0])
    pole = _unit(pole - axis * np.einsum("ki,ki->k", pole, axis)[:, None])
    cos_a = np.clip((a * a + d * d - b * b) / (2 * a * d), -1.0, 1.0)
    knee_new = u + a[:, None] * (cos_a[:, None] * axis + np.sqrt(1 - cos_a**2)[:, None] * pole)
    _turn_subtree(world, subtree[upper], _rotation_between(_unit(k - u), _unit(knee_new - u)), u)
    goal = u + d[:, None] * axis
    _turn_subtree(
        world, subtree[knee], _rotation_between(_unit(pos(foot) - knee_new), _unit(goal - knee_new)), knee_new
    )


def subtree_masks(parents: np.ndarray) -> np.ndarray:
    """(J, J) bool: row j marks joint j and all its descendants."""
    n = len(parents)
    mask = np.eye(n, dtype=bool)
    for j in range(n):
        p = parents[j]
        while p >= 0:
            mask[p, j] = True
            p = parents[p]
    return mask


def find_joint(names: list[str], patterns: list[str], what: str) -> int:
    """Index of the first joint whose name matches one of the regular expressions (case-insensitive)."""
    for pat in patterns:
        for i, name in enumerate(names):
            if re.search(pat, name, re.IGNORECASE):
                return i
    raise InputError(f"no {what} joint found among {', '.join(names)}; name it explicitly")


def leg_chain(parents: np.ndarray, hip: int, foot: int) -> list[int]:
    """The joints strictly between hip and foot, top down (the hip must be an ancestor of the foot)."""
    chain, p = [], parents[foot]
    while p >= 0 and p != hip:
        chain.append(int(p))
        p = parents[p]
    if p != hip:
        raise InputError("the hip joint must be an ancestor of both foot joints")
    return chain[::-1]


def cycle_world_matrices(
    skinned: Any,
    params: StepParams,
    times: np.ndarray,
    hip: int | str | None = None,
    right_foot: int | str | None = None,
    left_foot: int | str | None = None,
) -> np.ndarray:
    """Joint world matrices (K, J, 4, 4) of the cycle at times (K,) seconds (joints by index, name or
    auto)."""
    from ..gltf.skin import joint_world_matrices

    names = list(skinned.joint_names)

    def pick(key: int | str | None, pats: list[str], what: str) -> int:
        return skinned.joint_index(key) if key is not None else find_joint(names, pats, what)

    h = pick(hip, [r"hip|pelvis", r"root"], "hip")
    fr = pick(
        right_foot,
        [r"(right|\br|_r\b|\.r\b|r_).*(foot|ankle)", r"(foot|ankle).*(right|_r\b|\.r\b)"],
        "right foot",
    )
    fl = pick(
        left_foot,
        [r"(left|\bl|_l\b|\.l\b|l_).*(foot|ankle)", r"(foot|ankle).*(left|_l\b|\.l\b)"],
        "left foot",
    )
    parents = np.asarray(skinned.joint_parents)
    rest = joint_world_matrices(skinned)
    leg = 0.5 * (
        np.linalg.norm(rest[h, :3, 3] - rest[fr, :3, 3]) + np.linalg.norm(rest[h, :3, 3] - rest[fl, :3, 3])
    )
    if leg <= 0:
        raise InputError("the feet sit at the hip: cannot measure the leg length")
    off_r, off_l, off_h = foot_and_hip_offsets(params, times, leg)
    subtree = subtree_masks(parents)
    world = np.broadcast_to(rest, (len(off_r), *rest.shape)).copy()
    legs = [
        (foot, leg_chain(parents, h, foot), rest[foot, :3, 3] + off)
        for foot, off in ((fr, off_r), (fl, off_l))
    ]
    off_h[:, 1] -= np.max(
        [_crouch(rest, h, chain, foot, target, off_h) for foot, chain, target in legs], axis=0
    )
    trans = world[..., :3, 3]  # (K, J, 3) view
    trans[:, subtree[h]] += off_h[:, None]
    for foot, chain, target in legs:
        reach(world, subtree, chain, foot, target)
        turn = rest[foot, :3, :3] @ np.linalg.inv(world[:, foot, :3, :3])  # keep the foot level
        _turn_subtree(world, subtree[foot], turn, world[:, foot, :3, 3].copy())
    return world


def _crouch(rest: np.ndarray, hip: int, chain: list[int], foot: int, target: np.ndarray,
            off_h: np.ndarray) -> np.ndarray:
    """How far (K,) the hip must drop so a two-bone leg can still reach its foot target (0 if it can)."""
    if len(chain) < 2:
        return np.zeros(len(target))
    top = chain[-2]
    bones = [top, *chain[chain.index(top) + 1 :], foot]
    reach_len = 0.995 * sum(
        np.linalg.norm(rest[b, :3, 3] - rest[a, :3, 3]) for a, b in zip(bones[:-1], bones[1:], strict=True)
    )
    d = target - (rest[top, :3, 3] + off_h)  # the top joint moves with the hip
    flat = np.maximum(reach_len**2 - d[:, 0] ** 2 - d[:, 2] ** 2, 0.0)
    return np.maximum(-d[:, 1] - np.sqrt(flat), 0.0)


def step_cycle(skinned: Any, params: StepParams, frames: int = 24, **joints: Any) -> Poses:
    """One walk/run cycle of a skinned mesh (pdeanim.gltf.skin.SkinnedMesh) as Poses of frames + 1 frames
    (the last equals the first), times in seconds over one period 1 / f."""
    from ..gltf.skin import skin_vertices

    if not 2 <= int(frames) <= 10_000:
        raise ParameterError(f"frames must be in 2..10000, got {frames}")
    times = np.arange(int(frames) + 1) / (int(frames) * params.frequency)
    verts = skin_vertices(skinned, cycle_world_matrices(skinned, params, times, **joints))
    return make_poses(verts, skinned.faces, times, meta={"producer": "cyclic-skeletal", **params.to_dict()})
