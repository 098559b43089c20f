"""The Dem Bones peer of the compression benchmark (PyPI ``py-dem-bones``): linear blend skinning with 8, 16,
32, 64 and 128 bones and at most 4 influences per vertex, quantised (rest positions, quaternions and
translations at 10-16 bits; 8-bit weights and bone indices), each array zstd -19, faces with meshoptimizer's
index codec. Solved on the welded trajectories (seam duplicates merged, the remap in the file: Dem Bones fails
on unwelded meshes). Solves are cached on disk outside the repository (minutes each on the larger
sequences)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from peers_common import WeldedInput, faces_code, log, pack_payload, quantise, result

BONES = (8, 16, 32, 64, 128)
QUICK_BONES = (8, 16)
PRECISIONS = ((16, 16), (14, 14), (12, 12), (10, 12))
"""(rest position bits, quaternion and translation bits): the error of a few bones is mostly the skinning's,
so fewer bits may cost nothing."""
QUICK_PRECISIONS = ((16, 16), (12, 12))
ITERATIONS = 30
INFLUENCES = 4


def solve(name: str, X: np.ndarray, faces: np.ndarray, bones: int, cache: Path) -> dict:
    """Weights (B, V) and transforms (F, B, 4, 4) of Dem Bones with ``bones`` bones, cached on disk, with the
    solve's seconds and the 1-min load average at its start and end (None for a cache written without it)."""
    path = cache / f"dembones-{name}-{X.shape[0]}x{X.shape[1]}-b{bones}-i{ITERATIONS}.npz"
    if path.exists():
        with np.load(path) as d:
            load = [float(x) for x in d["load"]] if "load" in d.files else None
            return {"weights": d["weights"], "transforms": d["transforms"], "seconds": float(d["seconds"]),
                    "load": load}
    from py_dem_bones import solve_skinning

    load0, t = os.getloadavg()[0], time.perf_counter()
    res = solve_skinning(X[0].astype(np.float64), X.astype(np.float64), bones, faces=faces,
                         max_influences=INFLUENCES, iterations=ITERATIONS)
    secs, load = time.perf_counter() - t, [load0, os.getloadavg()[0]]
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, weights=res.weights, transforms=res.transforms, seconds=secs, load=np.array(load))
    log(f"{name}: dem bones {bones} bones solved in {secs:.1f} s (1-min load {load[0]:.1f} -> {load[1]:.1f})")
    return {"weights": res.weights, "transforms": res.transforms, "seconds": secs, "load": load}


def skin(rest: np.ndarray, W: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Linear blend skinning: rest (V, 3), weights (V, B), rotations (F, B, 3, 3), translations (F, B, 3)."""
    out = np.empty((len(R), len(rest), 3))
    for f in range(len(R)):  # one frame at a time keeps memory at V x B x 3
        P = np.einsum("bij,vj->bvi", R[f], rest) + T[f][:, None, :]
        out[f] = np.einsum("vb,bvi->vi", W, P)
    return out


def quantised_skinning(X: np.ndarray, weights: np.ndarray, M: np.ndarray, rest_bits: int,
                       bone_bits: int) -> tuple[np.ndarray, dict]:
    """The decoded frames and the arrays of a quantised Dem Bones file (top-4 weights renormalised)."""
    from scipy.spatial.transform import Rotation

    Wt = weights.T  # (V, B)
    F, B = M.shape[:2]
    top = np.argsort(-Wt, axis=1)[:, :INFLUENCES]
    wv = np.take_along_axis(Wt, top, 1)
    w8 = np.rint(wv / np.maximum(wv.sum(1, keepdims=True), 1e-12) * 255).astype(np.uint8)
    bone_dtype = np.uint8 if B <= 256 else np.uint16
    Wq = np.zeros_like(Wt)
    np.put_along_axis(Wq, top, w8 / 255.0, 1)
    quat = Rotation.from_matrix(M[..., :3, :3].reshape(-1, 3, 3)).as_quat().reshape(F, B, 4)
    q_rest, rest_dq, r_rest = quantise(X[0], axis=0, bits=rest_bits)
    q_quat, quat_dq, r_quat = quantise(quat, axis=(0, 2), bits=bone_bits)
    q_tr, tr_dq, r_tr = quantise(M[..., :3, 3], axis=(0, 2), bits=bone_bits)
    Rq = Rotation.from_quat(quat_dq.reshape(-1, 4)).as_matrix().reshape(F, B, 3, 3)
    arrays = {"rest": q_rest, "rest_range": r_rest, "weights": w8, "bones": top.astype(bone_dtype),
              "quaternions": q_quat, "quaternion_range": r_quat, "translations": q_tr,
              "translation_range": r_tr}
    return skin(rest_dq, Wq, Rq, tr_dq), arrays


def method_dembones(name: str, X: np.ndarray, faces: np.ndarray, cache: Path, quick: bool,
                    bones: tuple[int, ...] | None = None) -> list[dict]:
    """Dem Bones at each bone count (``bones``, default BONES), on the welded trajectories, quantised + zstd,
    faces and remap included."""
    w = WeldedInput(X, faces)
    fc = faces_code(w.faces, w.X.shape[1])
    rows = []
    for b in bones or (QUICK_BONES if quick else BONES):
        log(f"{name}: dem bones {b} bones")
        sol = solve(name, w.X, w.faces, b, cache)
        for rest_bits, bone_bits in QUICK_PRECISIONS if quick else PRECISIONS:
            approx, arrays = quantised_skinning(w.X, sol["weights"], sol["transforms"], rest_bits, bone_bits)
            approx = w.expand(approx)
            blob = pack_payload("dembones", {"faces": fc, **w.arrays(), **arrays})
            solved = sol["weights"].shape[0]
            setting = f"{b} bones ({solved} solved), rest {rest_bits}-bit, bones {bone_bits}-bit"
            rows.append(result("dembones", setting, blob, approx, X, solve_s=sol["seconds"],
                               solve_load=sol["load"]))
    return rows
