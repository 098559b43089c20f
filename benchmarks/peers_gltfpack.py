"""The gltfpack peer of the compression benchmark: a positions-only morph-target GLB of the frames (no NORMAL,
so gltfpack may merge duplicate vertices), packed with ``gltfpack -cc -vp N`` (N = 8..16, with and without
``-vpf``, with EXT and KHR meshopt compression), decoded back with meshoptimizer's decoder (node) and
scored against the source frames."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np
from peers_common import FPS, ROOT, log, result

PEERS_DIR = ROOT / "benchmarks" / "peers"
GLTFPACK_CLI = PEERS_DIR / "node_modules" / "gltfpack" / "cli.js"
DECODER = PEERS_DIR / "decode_meshopt.mjs"
VP_BITS = tuple(range(8, 17))
VARIANTS = ((), ("-vpf",), ("-ce", "khr"), ("-vpf", "-ce", "khr"))
"""Position attributes as integers (gltfpack's default) or floats (-vpf); EXT_meshopt_compression (default) or
KHR_meshopt_compression (-ce khr: its newer vertex codec is 5-10% smaller)."""
QUICK_VARIANTS = (("-ce", "khr"),)


def positions_morph_glb(X: np.ndarray, faces: np.ndarray, fps: float = FPS) -> bytes:
    """GLB of frames X (F, V, 3): base POSITION = frame 0, one POSITION-only morph target per later frame,
    indices, and a LINEAR weights animation with one key per frame (frame 0: all weights zero)."""
    from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder

    F, V = X.shape[:2]
    fr = X.astype(np.float32)
    b = GlbBuilder(generator="pdeanim benchmarks/peers_gltfpack.py")
    base = b.add_accessor(fr[0], target=ARRAY_BUFFER, minmax=True)
    targets = [{"POSITION": b.add_accessor(fr[f] - fr[0], target=ARRAY_BUFFER, minmax=True)}
               for f in range(1, F)]
    idx_type = np.uint16 if V < 65535 else np.uint32
    idx = b.add_accessor(np.asarray(faces, idx_type).reshape(-1), target=ELEMENT_ARRAY_BUFFER,
                         acc_type="SCALAR")
    weights = np.zeros((F, F - 1), np.float32)
    weights[np.arange(1, F), np.arange(F - 1)] = 1.0
    t_acc = b.add_accessor((np.arange(F) / fps).astype(np.float32), minmax=True, acc_type="SCALAR")
    w_acc = b.add_accessor(weights.reshape(-1), acc_type="SCALAR")
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": base}, "indices": idx, "mode": 4,
                                        "targets": targets}], "weights": [0.0] * (F - 1)}]
    b.doc["nodes"] = [{"mesh": 0}]
    b.doc["scenes"] = [{"nodes": [0]}]
    b.doc["scene"] = 0
    b.doc["animations"] = [{"samplers": [{"input": t_acc, "output": w_acc, "interpolation": "LINEAR"}],
                            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    return b.to_glb()


def match_vertices(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Index into Y's vertices of the nearest trajectory of every source vertex (gltfpack welds duplicate
    vertices and reorders them)."""
    from scipy.spatial import cKDTree

    pick = np.unique(np.linspace(0, len(X) - 1, min(len(X), 8)).astype(int))

    def feat(P: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.moveaxis(P[pick], 0, 1).reshape(P.shape[1], -1))

    return cKDTree(feat(Y)).query(feat(X), workers=1)[1]


def pack_and_score(src: Path, X: np.ndarray, flags: list[str], work: Path, timeout: float) -> dict | None:
    """One gltfpack run on ``src`` with ``flags``, decoded and scored; None (logged) when a tool fails."""
    from pdeanim.gltf.read import read_animated_poses

    tag = "".join(flags).replace("-", "_")
    packed, plain = work / f"packed{tag}.glb", work / f"plain{tag}.glb"
    t = time.perf_counter()
    p = subprocess.run(["node", str(GLTFPACK_CLI), "-i", str(src), "-o", str(packed), *flags],
                       capture_output=True, text=True, timeout=timeout)
    secs = time.perf_counter() - t
    if p.returncode != 0:
        log(f"gltfpack {' '.join(flags)} failed: {p.stderr[-300:]}")
        return None
    d = subprocess.run(["node", str(DECODER), str(packed), str(plain)], capture_output=True, text=True,
                       timeout=timeout)
    if d.returncode != 0:
        log(f"meshopt decode of gltfpack {' '.join(flags)} failed: {d.stderr[-300:]}")
        return None
    Y = read_animated_poses(plain, fps=FPS).vertices.astype(np.float64)
    if len(Y) != len(X):
        log(f"gltfpack {' '.join(flags)}: {len(Y)} frames decoded for {len(X)}; scored on the common prefix")
    m = min(len(Y), len(X))
    approx = Y[:m][:, match_vertices(X[:m], Y[:m])]
    row = result("gltfpack", " ".join(flags), packed.read_bytes(), approx, X[:m], pack_s=secs,
                 decoded_vertices=int(Y.shape[1]))
    packed.unlink()
    plain.unlink()
    return row


def method_gltfpack(X: np.ndarray, faces: np.ndarray, work: Path, timeout: float, quick: bool,
                    vp_bits: tuple[int, ...] | None = None, floats: bool = True) -> list[dict]:
    """Every ``-cc -vp N`` setting (N in ``vp_bits``, default 8..16) of every variant on the positions-only
    morph GLB (``floats=False`` leaves out the -vpf variants; quick: even N of KHR integer positions only)."""
    src = work / "frames-positions.glb"
    src.write_bytes(positions_morph_glb(X, faces))
    rows = []
    variants = QUICK_VARIANTS if quick else tuple(v for v in VARIANTS if floats or "-vpf" not in v)
    for variant in variants:
        for n in VP_BITS[::2] if quick else (vp_bits or VP_BITS):
            row = pack_and_score(src, X, ["-cc", "-vp", str(n), *variant], work, timeout)
            if row is not None:
                rows.append(row)
    src.unlink()
    return rows
