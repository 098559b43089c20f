"""Animation GLB sizes: pdeanim's writer (14-bit positions, byte normals, welded vertices, meshopt) against
``gltfpack -cc`` of the same frames with the same content, and against the raw float32 frames.

Cases: the two classes of model issue 23 measured, from public glTF sample models in tests/gltf/data (see
its LICENSES.md): a flat-shaded, textured, unwelded low-poly quadruped (Fox, its "Run": 1,728 corners, no
normals) and a skinned, textured, smooth humanoid (CesiumMan's walk, 3,273 vertices with normals), each
fitted to a clip (``pdeanim fit`` defaults) and exported as ``pdeanim export CLIP`` does (``plain``) and with
``--mesh SOURCE`` (``look``: the source's materials, texture, UVs and nodes). Optional: the demo clip (spot,
simulated and fitted as ``pdeanim demo`` does) and sequences of ../shared/data/sequences (frames as they are).

gltfpack gets a float32 morph-target GLB of exactly the same frames and content (what ``--no-quantize
--no-compress --no-weld`` writes: the same normals or none, the same UVs and texture); the ``gp pos-only``
column is gltfpack of positions only (no NORMAL at all: what issue 23 compared against). Precision: each row
prints the position grid step of both (relative to the frames' largest extent); besides our default 14 bits,
a second row uses the fewest bits whose step is no coarser than gltfpack's. ``verts`` is what each writes
(ours welds lossless: equal data in every frame; gltfpack welds on the first frame's data only).

    .venv/bin/python benchmarks/gltf_sizes.py [--sequences pcow] [--demo] [--validate] [--repeats 3]

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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pdeanim.gltf.compact import PackOptions, layout_animation_glb  # noqa: E402
from pdeanim.gltf.glb import pack_glb, unpack_glb  # noqa: E402
from pdeanim.gltf.layout import Layout, gltf_layout, plain_layout  # noqa: E402
from pdeanim.gltf.write import _check_times, _key_plan  # noqa: E402

_CANDIDATES = [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
SEQUENCES = next((p for p in _CANDIDATES if p.is_dir()), _CANDIDATES[0])
GLTFPACK = ROOT / "tools" / "gltfpack" / "node_modules" / ".bin" / "gltfpack"
MODELS = ROOT / "tests" / "gltf" / "data"
SOURCES = {"quadruped (Fox run)": (MODELS / "Fox.glb", "Run"),
           "humanoid (CesiumMan)": (MODELS / "CesiumMan.glb", None)}
FLOAT32 = dict(quantize=False, compress=False, weld=False)


@dataclass
class Case:
    """Frames to export: ``write(options, layout)`` gives the GLB that pdeanim writes for them."""

    label: str
    frames: np.ndarray  # (K, V, 3) float32, as exported
    write: Callable[[PackOptions, Layout | None], bytes]
    source: bytes | None = None  # the glTF whose look ``--mesh`` keeps


def clip_case(label: str, path: Path, animation: str | None, fps: float) -> Case:
    """A public model's animation sampled at ``fps``, fitted to a clip, exported as ``pdeanim export``."""
    from pdeanim.clip import load_clip
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.gltf.clipexport import clip_animation_glb, clip_duration, export_times
    from pdeanim.gltf.read import read_animated_poses

    src = path.read_bytes()
    parts = fit_poses(read_animated_poses(src, fps=fps, animation=animation), FitOptions())
    clip = load_clip(parts.topology, parts.coefficients)
    seconds = export_times(clip_duration(clip), fps)
    frames = np.asarray(clip.evaluate(seconds / clip_duration(clip)), np.float32).reshape(len(seconds), -1, 3)

    def write(options: PackOptions, layout: Layout | None) -> bytes:
        return clip_animation_glb(clip, fps, options=options,
                                  layout=layout or plain_layout(clip.faces, clip.n_vertices))

    return Case(label, frames, write, src)


def frames_case(label: str, frames: np.ndarray, faces: np.ndarray, times: np.ndarray) -> Case:
    """Frames as they are (no clip), written by the layout writer with a plain layout."""
    key_times, key_target, n = _key_plan(frames, _check_times(times, len(frames)), False)

    def write(options: PackOptions, layout: Layout | None) -> bytes:
        return layout_animation_glb(layout or plain_layout(faces, frames.shape[1]), frames, key_times,
                                    key_target, n, options=options)

    return Case(label, frames, write)


def demo_case(fps: float) -> Case:
    """The demo clip (spot, simulated and fitted with the demo's settings)."""
    from pdeanim.clip import load_clip
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.gltf.clipexport import clip_animation_glb, clip_duration, export_times
    from pdeanim.mesh.io import load_mesh
    from pdeanim.sim.scene import SceneParams
    from pdeanim.sim.simulate import simulate_mesh
    from pdeanim_service.demo import FIT, SAMPLE_MESH, SCENE

    with tempfile.TemporaryDirectory() as tmp:
        poses = simulate_mesh(load_mesh(SAMPLE_MESH), SceneParams.from_dict(SCENE), workdir=Path(tmp),
                              cache_dir=Path(tmp))
    parts = fit_poses(poses, FitOptions.from_dict(FIT))
    clip = load_clip(parts.topology, parts.coefficients)
    seconds = export_times(clip_duration(clip), fps)
    frames = np.asarray(clip.evaluate(seconds / clip_duration(clip)), np.float32).reshape(len(seconds), -1, 3)
    return Case("demo clip (spot)", frames, lambda o, lay: clip_animation_glb(
        clip, fps, options=o, layout=lay or plain_layout(clip.faces, clip.n_vertices)))


def sequence_case(name: str, fps: float) -> Case:
    """Frames, faces and times (evenly spaced at ``fps`` unless the file has ``times``) of a sequence."""
    with np.load(SEQUENCES / f"{name}.npz") as d:
        frames, faces = d["vertices"].astype(np.float32), d["faces"].astype(np.int64)
        times = d["times"].astype(np.float64) if "times" in d else np.arange(len(frames)) / fps
    return frames_case(name, frames, faces, times)


def positions_only(glb: bytes) -> bytes:
    """The GLB without any NORMAL (base or target): what gltfpack welds by position (and UV) alone."""
    doc, binary = unpack_glb(glb)
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            prim["attributes"].pop("NORMAL", None)
            for target in prim.get("targets", []):
                target.pop("NORMAL", None)
    return pack_glb(doc, binary or b"")


def gltfpack_cc(glb: bytes, tmp: Path) -> bytes:
    """``gltfpack -cc`` of a GLB."""
    src, out = tmp / "in.glb", tmp / "out.glb"
    src.write_bytes(glb)
    subprocess.run([str(GLTFPACK), "-cc", "-i", str(src), "-o", str(out)], check=True, capture_output=True)
    return out.read_bytes()


def grid_step(glb: bytes) -> float:
    """The position grid step of a quantised GLB in world units: the largest world scale of a node whose mesh
    has integer positions (the dequantising node's scale times its parents')."""
    from pdeanim.gltf.document import load_document
    from pdeanim.gltf.scene import world_matrices

    gd = load_document(glb)
    world = world_matrices(gd, {}, np.zeros(1))[0]
    def quantised(mesh: int) -> bool:
        prims = gd.doc["meshes"][mesh]["primitives"]
        return any(gd.doc["accessors"][p["attributes"]["POSITION"]]["componentType"] != 5126 for p in prims)

    steps = [np.linalg.norm(world[i][:3, :3], axis=0).max() for i, node in enumerate(gd.doc["nodes"])
             if "mesh" in node and quantised(node["mesh"])]
    return float(max(steps, default=0.0))


def written(glb: bytes) -> tuple[int, str]:
    """Vertices written (all primitives) and which normals: none, base (first frame only) or targets."""
    doc, _ = unpack_glb(glb)
    prims = [p for m in doc["meshes"] for p in m["primitives"]]
    count = sum(doc["accessors"][p["attributes"]["POSITION"]]["count"] for p in prims)
    if not any("NORMAL" in p["attributes"] for p in prims):
        return count, "none"
    return count, "targets" if any("NORMAL" in t for p in prims for t in p.get("targets", [])) else "base"


def measure(case: Case, look: bool, options: PackOptions, repeats: int) -> tuple[bytes, float]:
    """Our GLB and the median seconds to write it."""
    builds, glb = [], b""
    for _ in range(repeats):
        layout = gltf_layout(case.source) if look else None
        start = time.perf_counter()
        glb = case.write(options, layout)
        builds.append(time.perf_counter() - start)
    return glb, statistics.median(builds)


def rows(case: Case, args: argparse.Namespace) -> None:
    """Print the rows of one case: plain and (with a source) look, each normals setting that differs."""
    extent = float(np.ptp(case.frames.reshape(-1, 3), axis=0).max())
    raw = case.frames.nbytes
    for look in (False, True) if case.source is not None else (False,):
        layout = (lambda: gltf_layout(case.source)) if look else (lambda: None)
        seen = set()
        for normals in (True, False):
            plain = case.write(PackOptions(normals=normals, **FLOAT32), layout())
            if written(plain)[1] in seen:
                continue  # a flat-shaded source has no normals either way
            seen.add(written(plain)[1])
            with tempfile.TemporaryDirectory() as tmp:
                gp = gltfpack_cc(plain, Path(tmp))
                gp_pos = gltfpack_cc(positions_only(plain), Path(tmp))
            matched = int(np.clip(np.ceil(np.log2(extent / grid_step(gp) + 1)), 8, 15))  # step <= gltfpack's
            for bits in sorted({args.bits, matched}, reverse=True):
                options = PackOptions(normals=normals, position_bits=bits)
                glb, build = measure(case, look, options, args.repeats)
                (ours_v, kind), (gp_v, _) = written(glb), written(gp)
                shape = f"{case.frames.shape[0]} x {case.frames.shape[1]}"
                print(f"{case.label:<21} {'look' if look else 'plain':<5} {kind:<7} {shape:>11} "
                      f"{ours_v:>6}/{gp_v:<6} {bits:>4} {raw:>10,} {len(gp_pos):>10,} {len(gp):>10,} "
                      f"{grid_step(gp) / extent:>7.1e} {len(glb):>10,} {grid_step(glb) / extent:>7.1e} "
                      f"{len(glb) / len(gp):>6.2f} {len(glb) / len(gp_pos):>6.2f} {len(glb) / raw:>6.3f} "
                      f"{build:>6.2f}{'  default' if bits == args.bits and not normals else ''}", flush=True)
                if args.validate:
                    from pdeanim.gltf.validate import assert_glb_clean

                    assert_glb_clean(glb, f"{case.label} look={look} normals={normals} bits={bits}")


def main() -> int:
    """Print one table row per case, look and normals setting."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", nargs="*", default=[], help="sequences of ../shared/data/sequences too")
    ap.add_argument("--demo", action="store_true", help="the demo clip too (it simulates spot first)")
    ap.add_argument("--no-models", action="store_true", help="skip the quadruped and humanoid models")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--bits", type=int, default=14, help="position bits of ours (default 14, the writer's "
                    "default); a second row uses the fewest bits whose step is no coarser than gltfpack's")
    ap.add_argument("--validate", action="store_true", help="also run the Khronos validator on our GLBs")
    args = ap.parse_args()
    if not GLTFPACK.exists():
        print(f"gltfpack not found at {GLTFPACK}: run script/setup (npm ci in tools/gltfpack)")
        return 2
    loaders: list[Callable[[], Case]] = []
    if not args.no_models:
        loaders += [lambda lab=label, s=src: clip_case(lab, *s, args.fps) for label, src in SOURCES.items()]
    if args.demo:
        loaders.append(lambda: demo_case(args.fps))
    loaders += [lambda n=name: sequence_case(n, args.fps) for name in args.sequences]
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("plain = `pdeanim export CLIP`, look = with --mesh SOURCE; normals: none (flat), base, targets; "
          "step = position grid step / largest extent of the frames; verts = written by ours/gltfpack; "
          "/gppos = ours / gltfpack of positions only; default = what an export writes unless told otherwise")
    print(f"{'case':<21} {'kind':<5} {'normals':<7} {'frames x V':>11} {'verts':>13} {'bits':>4} "
          f"{'raw f32':>10} {'gp pos-only':>10} {'gltfpack':>10} {'gp step':>7} {'ours':>10} {'step':>7} "
          f"{'ours/gp':>6} {'/gppos':>6} {'/raw':>6} {'build':>6}")
    for load in loaders:
        rows(load(), args)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
