"""Animation GLB sizes: pdeanim's writer (14-bit positions, byte normals, EXT_meshopt_compression) against
``gltfpack -cc`` of the same frames and against the raw float32 frames, for the demo clip (spot simulated
and fitted as ``pdeanim demo`` does) and sequences of ../shared/data/sequences (read from there, never
copied). Each case is measured with and without per-frame normal deltas; gltfpack gets a plain float32
morph-target GLB of exactly the same frames (with or without NORMAL targets) as input. Precision: each
row prints the position grid step of both (relative to the frames' largest extent); besides our default
14 bits, a second row uses the fewest bits whose step is no coarser than gltfpack's.

    .venv/bin/python benchmarks/gltf_sizes.py [--sequences pcow horse-collapse] [--no-demo] [--validate]

gltfpack comes from npm (``tools/gltfpack``, installed by script/setup). Build times are medians of
``--repeats`` runs; the load average is printed because the machine may be shared.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pdeanim.gltf.compact import PackOptions, layout_animation_glb  # noqa: E402
from pdeanim.gltf.layout import plain_layout  # noqa: E402
from pdeanim.gltf.write import _check_times, _key_plan, animation_glb  # noqa: E402

_CANDIDATES = [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
SEQUENCES = next((p for p in _CANDIDATES if p.is_dir()), _CANDIDATES[0])
GLTFPACK = ROOT / "tools" / "gltfpack" / "node_modules" / ".bin" / "gltfpack"


def demo_frames(fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames of the demo clip (spot, simulated and fitted with the demo's settings) sampled at ``fps``."""
    from pdeanim.clip import load_clip
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.gltf.clipexport import clip_duration, export_times
    from pdeanim.mesh.io import load_mesh
    from pdeanim.sim.scene import SceneParams
    from pdeanim.sim.simulate import simulate_mesh
    from service.demo import FIT, SAMPLE_MESH, SCENE

    with tempfile.TemporaryDirectory() as tmp:
        poses = simulate_mesh(load_mesh(SAMPLE_MESH), SceneParams.from_dict(SCENE), workdir=Path(tmp),
                              cache_dir=Path(tmp))
    parts = fit_poses(poses, FitOptions.from_dict(FIT))
    clip = load_clip(parts.topology, parts.coefficients)
    seconds = export_times(clip_duration(clip), fps)
    t = seconds / clip_duration(clip)
    return np.asarray(clip.evaluate(t), np.float32).reshape(len(t), -1, 3), np.asarray(clip.faces), seconds


def sequence_frames(name: str, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames, faces and times (evenly spaced at ``fps`` unless the file has ``times``) of a sequence."""
    with np.load(SEQUENCES / f"{name}.npz") as d:
        frames, faces = d["vertices"].astype(np.float32), d["faces"].astype(np.int64)
        times = d["times"].astype(np.float64) if "times" in d else np.arange(len(frames)) / fps
    return frames, faces, times


def ours(frames: np.ndarray, faces: np.ndarray, times: np.ndarray, normals: bool, bits: int) -> bytes:
    """pdeanim's animation GLB (what the API and ``pdeanim export`` write, here with ``bits`` per axis)."""
    layout = plain_layout(faces, frames.shape[1])
    key_times, key_target, n = _key_plan(frames, _check_times(times, len(frames)), False)
    return layout_animation_glb(layout, frames, key_times, key_target, n,
                                options=PackOptions(normals=normals, position_bits=bits))


def gltfpack_cc(frames: np.ndarray, faces: np.ndarray, times: np.ndarray, normals: bool,
                tmp: Path) -> tuple[bytes, int]:
    """``gltfpack -cc`` run on a float32 morph-target GLB of the same frames, and that input's size (what
    ``--no-quantize --no-compress`` writes, and what the API served before the compact writer)."""
    src, out = tmp / "in.glb", tmp / "out.glb"
    src.write_bytes(animation_glb(frames, times, faces, normals=normals))
    subprocess.run([str(GLTFPACK), "-cc", "-i", str(src), "-o", str(out)], check=True, capture_output=True)
    return out.read_bytes(), src.stat().st_size


def grid_step(glb: bytes) -> float:
    """The position grid step of a quantised GLB: the largest node scale (the dequantising node's)."""
    from pdeanim.gltf.glb import unpack_glb

    doc, _ = unpack_glb(glb)
    return max(max(n.get("scale", [0.0])) for n in doc["nodes"])


def main() -> int:
    """Print one table row per case and normals setting."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", nargs="*", default=["pcow", "horse-collapse"])
    ap.add_argument("--no-demo", action="store_true", help="skip the demo clip (it simulates spot first)")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--bits", type=int, default=14, help="position bits of ours (default 14, the writer's "
                    "default); a second row uses the fewest bits whose step is no coarser than gltfpack's")
    ap.add_argument("--validate", action="store_true", help="also run the Khronos validator on our GLBs")
    args = ap.parse_args()
    if not GLTFPACK.exists():
        print(f"gltfpack not found at {GLTFPACK}: run script/setup (npm ci in tools/gltfpack)")
        return 2
    cases = [] if args.no_demo else [("demo clip (spot)", lambda: demo_frames(args.fps))]
    cases += [(name, lambda n=name: sequence_frames(n, args.fps)) for name in args.sequences]
    print(f"load average before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    print("step = position grid step / largest bounding-box extent of the frames (smaller is finer)")
    header = (f"{'case':<20} {'frames x verts':>14} {'nrm':>3} {'bits':>4} {'raw f32':>11} {'plain GLB':>11} "
              f"{'gltfpack -cc':>12} {'gp step':>8} {'ours':>11} {'ours step':>9} {'ours/gp':>7} "
              f"{'ours/raw':>8} {'build s':>7}")
    print(header)
    for label, load in cases:
        frames, faces, times = load()
        raw = frames.nbytes
        extent = float(np.ptp(frames.reshape(-1, 3), axis=0).max())
        for normals in (True, False):
            with tempfile.TemporaryDirectory() as tmp:
                gp, plain = gltfpack_cc(frames, faces, times, normals, Path(tmp))
            matched = int(np.clip(np.ceil(np.log2(extent / grid_step(gp) + 1)), 8, 15))  # step <= gltfpack's
            for bits in sorted({args.bits, matched}, reverse=True):
                builds, glb = [], b""
                for _ in range(args.repeats):
                    start = time.perf_counter()
                    glb = ours(frames, faces, times, normals, bits)
                    builds.append(time.perf_counter() - start)
                shape = f"{frames.shape[0]} x {frames.shape[1]}"
                print(f"{label:<20} {shape:>14} {'yes' if normals else 'no':>3} {bits:>4} {raw:>11,} "
                      f"{plain:>11,} {len(gp):>12,} {grid_step(gp) / extent:>8.1e} {len(glb):>11,} "
                      f"{grid_step(glb) / extent:>9.1e} {len(glb) / len(gp):>7.2f} {len(glb) / raw:>8.3f} "
                      f"{statistics.median(builds):>7.2f}", flush=True)
                if args.validate:
                    from pdeanim.gltf.validate import assert_glb_clean

                    assert_glb_clean(glb, f"{label} normals={normals}")
    print(f"load average after: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
