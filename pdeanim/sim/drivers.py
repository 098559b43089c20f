"""Turn scene regions into simulation points, and driver keyframes into prescribed rigid motion over time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..errors import ParameterError
from .embedding import Embedding


def select_points(region: dict, points: np.ndarray, embedding: Embedding, n_vertices: int) -> np.ndarray:
    """(K,) sorted indices of the tet points (N, 3) a region dict selects; ParameterError if none."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    scale = hi - lo if region.get("relative", False) else np.ones(3)
    offset = lo if region.get("relative", False) else np.zeros(3)
    if "indices" in region:
        idx = np.asarray(region["indices"], np.int64)
        if idx.max() >= n_vertices:
            raise ParameterError(f"pin index {int(idx.max())} is out of range for {n_vertices} vertices")
        chosen = np.unique(embedding.corners[idx])
    elif "box" in region:
        box = np.asarray(region["box"], np.float64)
        bmin, bmax = offset + scale * box[:3], offset + scale * box[3:]
        chosen = np.flatnonzero(np.all((points >= bmin) & (points <= bmax), axis=1))
    else:
        plane = np.asarray(region["plane"], np.float64)
        origin = offset + scale * plane[:3]
        chosen = np.flatnonzero((points - origin) @ plane[3:] <= 0)
    if len(chosen) == 0:
        raise ParameterError(f"region {region} selects no simulation point (the mesh spans {lo.tolist()} to "
                             f"{hi.tolist()})")
    return chosen


@dataclass(frozen=True)
class RigidPath:
    """Rotation (slerp) and translation (lerp) keyframes at normalised times (K,) about a center (3,)."""

    times: np.ndarray
    rotations: Rotation
    translations: np.ndarray
    center: np.ndarray
    slerp: Slerp | None = None

    @classmethod
    def from_keyframes(cls, keyframes: list[dict], center: np.ndarray) -> RigidPath:
        """Keyframes as in SceneParams; an identity key at t = 0 is added when the first key is later."""
        keys = list(keyframes)
        if keys[0]["t"] > 0:
            keys.insert(0, {"t": 0.0})
        times = np.array([k["t"] for k in keys], np.float64)
        rotvecs = []
        for k in keys:
            ax, ay, az, deg = k.get("rotate", (1.0, 0.0, 0.0, 0.0))
            axis = np.array([ax, ay, az], np.float64)
            rotvecs.append(axis / np.linalg.norm(axis) * np.deg2rad(deg))
        translations = np.array([k.get("translate", (0.0, 0.0, 0.0)) for k in keys], np.float64)
        rotations = Rotation.from_rotvec(np.array(rotvecs))
        slerp = Slerp(times, rotations) if len(times) > 1 else None
        return cls(times, rotations, translations, np.asarray(center, np.float64), slerp)

    def transform(self, s: float) -> tuple[Rotation, np.ndarray]:
        """Rotation and translation at normalised time s (held constant outside the keyframes)."""
        s = float(np.clip(s, self.times[0], self.times[-1]))
        if self.slerp is None:
            return self.rotations[0], self.translations[0]
        rot = self.slerp([s])[0]
        trans = np.array([np.interp(s, self.times, self.translations[:, d]) for d in range(3)])
        return rot, trans

    def apply(self, rest: np.ndarray, s: float) -> np.ndarray:
        """(K, 3) positions of rest points (K, 3) at normalised time s: R (x - c) + c + T."""
        rot, trans = self.transform(s)
        return rot.apply(rest - self.center) + self.center + trans


@dataclass(frozen=True)
class Kinematics:
    """Prescribed positions of the fixed points: pinned ones stay at rest, driven ones follow their path."""

    fixed: np.ndarray
    rest: np.ndarray
    groups: tuple[tuple[np.ndarray, RigidPath], ...]
    duration: float

    def __call__(self, t: float) -> np.ndarray:
        """(K, 3) positions of ``fixed`` at time t seconds."""
        out = self.rest.copy()
        s = t / self.duration if self.duration > 0 else 0.0
        for rows, path in self.groups:
            out[rows] = path.apply(self.rest[rows], s)
        return out


def build_kinematics(pins: list[dict], drivers: list[dict], points: np.ndarray, embedding: Embedding,
                     n_vertices: int, duration: float) -> Kinematics:
    """Fixed tet points (pins and driven regions; a driver wins over a pin) and their motion."""
    pinned = [select_points(r, points, embedding, n_vertices) for r in pins]
    driven = [select_points(d["region"], points, embedding, n_vertices) for d in drivers]
    fixed = np.unique(np.concatenate(pinned + driven)) if pinned or driven else np.zeros(0, np.int64)
    groups = []
    for d, idx in zip(drivers, driven, strict=True):
        center = np.asarray(d.get("center", points[idx].mean(axis=0)), np.float64)
        groups.append((np.searchsorted(fixed, idx), RigidPath.from_keyframes(d["keyframes"], center)))
    return Kinematics(fixed, points[fixed].copy(), tuple(groups), duration)
