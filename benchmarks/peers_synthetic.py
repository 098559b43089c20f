"""Small low-rank animations the compression benchmark makes itself (deterministic, written to a scratch
folder for the CLI, never into the repository):

* ``blend3-spot``: three shapes of Spot (the packaged demo mesh; Keenan Crane, public domain) blended with
  smooth weights: the mesh, a bulge along the normals around the head, and a squash-and-stretch. The
  displacement from frame 0 has rank 2.
* ``rig4-tube``: an open tube of 384 vertices skinned procedurally to a chain of 4 bones (smooth weights, at
  most 2 influences) bending and twisting with sinusoids.
"""

from __future__ import annotations

import numpy as np
from peers_common import ROOT

FRAMES = 96


def blend3_spot(frames: int = FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """(F, V, 3) frames and faces of Spot blended between three shapes (rank-2 motion)."""
    from pdeanim.gltf.normals import vertex_normals
    from pdeanim.mesh.io import load_mesh

    mesh = load_mesh(ROOT / "pdeanim" / "data" / "spot.obj")
    S0, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int32)
    diag = float(np.linalg.norm(S0.max(0) - S0.min(0)))
    head = S0[np.argmax(S0[:, 2])]
    bump = np.exp(-np.sum((S0 - head) ** 2, axis=1) / (2 * (0.2 * diag) ** 2))
    S1 = S0 + 0.08 * diag * bump[:, None] * vertex_normals(S0.astype(np.float32), faces)
    c = S0.mean(0)
    S2 = c + (S0 - c) * np.array([0.9, 1.25, 0.9])
    t = np.linspace(0.0, 1.0, frames)[:, None, None]
    a = np.sin(2 * np.pi * t) ** 2
    b = 0.5 * (1 - np.cos(3 * np.pi * t))
    return S0 + a * (S1 - S0) + b * (S2 - S0), faces


def tube(rings: int = 24, around: int = 16, length: float = 4.0, radius: float = 0.35) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
    """An open tube along x: (rings * around, 3) vertices and its triangles."""
    x = np.linspace(0.0, length, rings)[:, None]
    a = np.linspace(0.0, 2 * np.pi, around, endpoint=False)[None, :]
    verts = np.stack(np.broadcast_arrays(x, radius * np.cos(a), radius * np.sin(a)), -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(around), indexing="ij")
    v00, v01 = i * around + j, i * around + (j + 1) % around
    v10, v11 = v00 + around, v01 + around
    faces = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3),
                            np.stack([v00, v11, v01], -1).reshape(-1, 3)])
    return verts, faces.astype(np.int32)


def rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations by ``angle`` (F,) about coordinate axis ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((len(angle), 3, 3))
    i, j = [k for k in range(3) if k != axis]
    R[:, axis, axis] = 1.0
    R[:, i, i], R[:, i, j], R[:, j, i], R[:, j, j] = c, -s, s, c
    return R


def rig4_tube(frames: int = FRAMES, bones: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(F, V, 3) frames and faces of a tube skinned to a chain of ``bones`` bones along x."""
    rest, faces = tube()
    length = rest[:, 0].max()
    joints = np.linspace(0.0, length, bones + 1)[:-1]
    centres = joints + 0.5 * length / bones
    w = np.exp(-(((rest[:, 0:1] - centres[None]) / (0.35 * length / bones)) ** 2))
    w[w < np.sort(w, axis=1)[:, -2:-1]] = 0.0  # at most 2 influences
    w /= w.sum(1, keepdims=True)
    t = np.linspace(0.0, 1.0, frames)
    G_R, G_T = np.broadcast_to(np.eye(3), (frames, 3, 3)), np.zeros((frames, 3))
    out = np.zeros((frames, len(rest), 3))
    for b in range(bones):  # a chain: each bone turns about its joint, after its parent's motion
        bend = rotation(2, 0.45 * np.sin(2 * np.pi * (t + 0.15 * b)))
        twist = rotation(0, 0.3 * np.sin(2 * np.pi * (2 * t + 0.3 * b)))
        R = bend @ twist
        p = np.array([joints[b], 0.0, 0.0])
        T = p - R @ p  # rotation about the joint at rest
        G_T = np.einsum("fij,fj->fi", G_R, T) + G_T
        G_R = G_R @ R
        out += w[None, :, b:b + 1] * (np.einsum("fij,vj->fvi", G_R, rest) + G_T[:, None, :])
    return out, faces


SYNTHETIC = {"blend3-spot": blend3_spot, "rig4-tube": rig4_tube}
