"""Geometry of glTF mesh primitives: positions, triangles (from TRIANGLES, STRIP or FAN; none for points and
lines), morph-target position offsets, and skin joints/weights."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .document import GltfDocument


@dataclass
class Primitive:
    """positions (V, 3) f64, faces (T, 3) i64 local indices, targets (M, V, 3) f64 position offsets,
    joints (V, n) i64 and weights (V, n) f64 (n = 0 when not skinned)."""

    positions: np.ndarray
    faces: np.ndarray
    targets: np.ndarray
    joints: np.ndarray
    weights: np.ndarray


def _triangles(mode: int, idx: np.ndarray) -> np.ndarray:
    n = len(idx)
    if mode == 4:
        return idx[: n - n % 3].reshape(-1, 3)
    if n < 3 or mode not in (5, 6):
        return np.zeros((0, 3), np.int64)
    i = np.arange(n - 2)
    if mode == 5:  # strip: every other triangle flips to keep the winding
        even = i % 2 == 0
        return np.stack(
            [np.where(even, idx[i], idx[i + 1]), np.where(even, idx[i + 1], idx[i]), idx[i + 2]], 1
        )
    return np.stack([np.full(n - 2, idx[0]), idx[i + 1], idx[i + 2]], 1)  # fan


def _influences(gd: GltfDocument, attrs: dict, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    sets = sorted(int(k.split("_")[1]) for k in attrs if k.startswith("JOINTS_"))
    if not sets:
        return np.zeros((n_vertices, 0), np.int64), np.zeros((n_vertices, 0))
    joints, weights = [], []
    for s in sets:
        if f"WEIGHTS_{s}" not in attrs:
            raise gd.error(f"primitive has JOINTS_{s} without WEIGHTS_{s}")
        joints.append(gd.accessor(attrs[f"JOINTS_{s}"]).astype(np.int64))
        weights.append(gd.accessor(attrs[f"WEIGHTS_{s}"]))
    j, w = np.concatenate(joints, axis=1), np.concatenate(weights, axis=1)
    if j.shape != w.shape or len(j) != n_vertices:
        raise gd.error("skin JOINTS and WEIGHTS accessors do not match the vertex count")
    return j, w


def read_primitive(gd: GltfDocument, prim: dict) -> Primitive:
    """Decode one primitive; a primitive without POSITION is an error."""
    attrs = prim.get("attributes", {})
    if "POSITION" not in attrs:
        raise gd.error("a glTF mesh primitive has no POSITION attribute")
    pos = gd.accessor(attrs["POSITION"]).astype(np.float64)
    if pos.shape[1] != 3:
        raise gd.error("POSITION must be VEC3")
    n = len(pos)
    mode = int(prim.get("mode", 4))
    idx = gd.accessor(prim["indices"])[:, 0].astype(np.int64) if "indices" in prim else np.arange(n)
    if len(idx) and (idx.min() < 0 or idx.max() >= n):
        raise gd.error(f"primitive indices out of range [0, {n})")
    faces = _triangles(mode, idx)
    targets = [gd.accessor(t["POSITION"]) if "POSITION" in t else np.zeros((n, 3))
               for t in prim.get("targets", [])]
    if any(t.shape != (n, 3) for t in targets):
        raise gd.error("a morph target's POSITION does not match the primitive's vertex count")
    tgt = np.stack(targets) if targets else np.zeros((0, n, 3))
    joints, weights = _influences(gd, attrs, n)
    return Primitive(pos, faces, tgt, joints, weights)
