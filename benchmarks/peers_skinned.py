"""The skinned-asset peer of the compression benchmark: for a skinned glTF input, the source's own skeletal
animation after ``gltfpack -cc`` (EXT and KHR meshopt compression). Counted: the animation and skin data (the
animation samplers' keys, the inverse bind matrices, JOINTS/WEIGHTS and their JSON); the mesh and its look
are counted on neither side (the clip side: its coefficients part, bone layer and residual curves; its
topology part holds the mesh). Decoded with meshoptimizer's decoder and scored against the source frames."""

from __future__ import annotations

import json
import struct
import subprocess
import time
from pathlib import Path

import numpy as np
from peers_common import FPS, log, result, zstd19
from peers_gltfpack import DECODER, GLTFPACK_CLI, match_vertices

VARIANTS = (("-cc",), ("-cc", "-ce", "khr"))


def glb_chunks(blob: bytes) -> tuple[dict, bytes]:
    """(JSON, BIN) of a GLB."""
    doc, binary, offset = None, b"", 12
    while offset < len(blob):
        length, kind = struct.unpack_from("<II", blob, offset)
        body = blob[offset + 8:offset + 8 + length]
        if kind == 0x4E4F534A:
            doc = json.loads(body)
        elif kind == 0x004E4942:
            binary = body
        offset += 8 + length
    return doc, binary


def animation_skin_bytes(blob: bytes) -> tuple[int, bytes]:
    """(bytes, the bytes themselves) of a GLB's animation and skin data: the buffer views (as stored,
    compressed where meshopt compresses them) of animation samplers, inverse bind matrices and JOINTS_n /
    WEIGHTS_n, plus the JSON of its animations and skins."""
    doc, binary = glb_chunks(blob)
    accessors = set()
    for anim in doc.get("animations", []):
        for s in anim["samplers"]:
            accessors |= {s["input"], s["output"]}
    accessors |= {s["inverseBindMatrices"] for s in doc.get("skins", []) if "inverseBindMatrices" in s}
    for mesh in doc.get("meshes", []):
        for prim in mesh["primitives"]:
            accessors |= {a for k, a in prim["attributes"].items() if k.startswith(("JOINTS_", "WEIGHTS_"))}
    views = sorted({doc["accessors"][a]["bufferView"] for a in accessors
                    if "bufferView" in doc["accessors"][a]})
    data = []
    for v in views:
        view = doc["bufferViews"][v]
        ext = (view.get("extensions") or {})
        ext = ext.get("EXT_meshopt_compression") or ext.get("KHR_meshopt_compression") or view
        start = ext.get("byteOffset", 0)
        data.append(binary[start:start + ext["byteLength"]])
    meta = json.dumps({"animations": doc.get("animations", []), "skins": doc.get("skins", [])},
                      separators=(",", ":")).encode()
    payload = b"".join(data) + meta
    return len(payload), payload


def method_skinned(src: Path, X: np.ndarray, work: Path, timeout: float) -> list[dict]:
    """The source's own skinned animation after gltfpack -cc (each variant), scored on the source frames."""
    from pdeanim.gltf.read import read_animated_poses

    rows = []
    for flags in VARIANTS:
        tag = "".join(flags).replace("-", "_")
        packed, plain = work / f"skinned{tag}.glb", work / f"skinned-plain{tag}.glb"
        t = time.perf_counter()
        p = subprocess.run(["node", str(GLTFPACK_CLI), "-i", str(src), "-o", str(packed), *flags],
                           capture_output=True, text=True, timeout=timeout)
        secs = time.perf_counter() - t
        d = None if p.returncode else subprocess.run(["node", str(DECODER), str(packed), str(plain)],
                                                     capture_output=True, text=True, timeout=timeout)
        if p.returncode or d.returncode:
            log(f"skinned gltfpack {' '.join(flags)} failed: {(p.stderr or d.stderr)[-300:]}")
            continue
        Y = read_animated_poses(plain, fps=FPS).vertices.astype(np.float64)
        m = min(len(Y), len(X))
        approx = Y[:m][:, match_vertices(X[:m], Y[:m])]
        size, payload = animation_skin_bytes(packed.read_bytes())
        rows.append(result("skinned", " ".join(flags) + " (animation + skin)", size, approx, X[:m],
                           wire=len(zstd19(payload)), pack_s=secs, glb_bytes=packed.stat().st_size))
    return rows
