"""Animation GLB sizes: the default export of a clip (``pdeanim export CLIP``: a position grid no finer than
the clip's own error needs, byte normals, welded vertices, EXT_meshopt_compression) against ``gltfpack -cc``
of exactly the same frames, at gltfpack's best settings for the same error, as files and on the wire.

Cases: the two classes of model issue 23 measured, from public glTF sample models in tests/gltf/data (see
its LICENSES.md): a flat-shaded, textured, unwelded low-poly quadruped (Fox, its "Run") and a skinned,
textured, smooth humanoid (CesiumMan's walk), exported as ``pdeanim export CLIP`` does (``plain``) and with
``--mesh SOURCE`` (``look``: the source's materials, texture, UVs and nodes); and the sequences of the
compression benchmark (../shared/data/sequences, read in place), each fitted to a clip with the library's
fit defaults (``FitOptions()``: rel. RMS 2e-3 of the diagonal, no bone layer) and exported ``plain``.
Every clip is sampled at 30 fps.

The peer, fairly:

- **Same frames.** gltfpack gets a float32 morph-target GLB of exactly the frames our export holds (the
  clip evaluated at the export's times), with the same UVs and texture for ``look``, and no normals at all
  (what ``--no-quantize --no-compress --no-weld`` writes, less every NORMAL: ours carries the first frame's
  normals, so this favours gltfpack).
- **Same error.** Both GLBs are decoded (our reader decodes EXT_meshopt_compression) and scored against the
  frames (vertices matched by trajectory: both weld). gltfpack's best settings are the smallest wire bytes
  over ``-cc -vp N`` (N = 8..16) with integer and with float (``-vpf``) positions, among the settings whose
  RMS error is no larger than ours; ``gp -cc`` is its default (-vp 14) for reference.
- **Bytes as they travel.** ``wire`` is zstd -19 of each file (the compression benchmark's content coding);
  the goal is judged on the wire and printed beside the file ratio.

Goal (issue 32): the default animation GLB at most 1.2x ``gltfpack -cc`` on every case, printed as met /
NOT met beside each figure. ``--khr`` also prints gltfpack's KHR_meshopt_compression (``-ce khr``, its newer
vertex codec, which the EXT extension that three.js's GLTFLoader reads does not allow) for information.

    .venv/bin/python benchmarks/gltf_sizes.py [--sequences pcow horse-collapse ...] [--validate] [--khr]

gltfpack comes from npm (``tools/gltfpack``, installed by script/setup). The load average is printed
because the machine may be shared; bytes and errors do not depend on it.
"""

from __future__ import annotations

import argparse
import os
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

from pdeanim.gltf.compact import PackOptions  # noqa: E402
from pdeanim.gltf.glb import pack_glb, unpack_glb  # noqa: E402
from pdeanim.gltf.layout import Layout, gltf_layout, plain_layout  # noqa: E402

_CANDIDATES = [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
SEQUENCES = next((p for p in _CANDIDATES if p.is_dir()), _CANDIDATES[0])
GLTFPACK = ROOT / "tools" / "gltfpack" / "node_modules" / ".bin" / "gltfpack"
MODELS = ROOT / "tests" / "gltf" / "data"
SOURCES = {"quadruped (Fox run)": (MODELS / "Fox.glb", "Run"),
           "humanoid (CesiumMan)": (MODELS / "CesiumMan.glb", None)}
FLOAT32 = dict(quantize=False, compress=False, weld=False)
FPS = 30.0
GOAL = 1.2
VP_BITS = range(8, 17)
WIRE_LEVEL = 19


@dataclass
class Case:
    """A fitted clip: ``frames`` (K, V, 3) float32 as exported, ``write(options, layout)`` its GLB (options
    None: the default export), ``source`` the glTF whose look ``--mesh`` keeps, ``fit`` its fit's errors."""

    label: str
    frames: np.ndarray
    write: Callable[[PackOptions | None, Layout | None], bytes]
    fit: dict
    fit_s: float
    source: bytes | None = None


def fitted_case(label: str, poses, source: bytes | None = None) -> Case:  # noqa: ANN001 - Poses
    """Poses fitted with the fit defaults and sampled as ``pdeanim export`` samples them."""
    from pdeanim.clip import load_clip
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.gltf.clipexport import clip_animation_glb, clip_duration, export_times

    start = time.perf_counter()
    parts = fit_poses(poses, FitOptions())
    fit_s = time.perf_counter() - start
    clip = load_clip(parts.topology, parts.coefficients)
    seconds = export_times(clip_duration(clip), FPS)
    t = seconds / clip_duration(clip)
    frames = np.asarray(clip.evaluate(t), np.float32).reshape(len(seconds), -1, 3)
    if clip.looping and len(frames) > 1:
        frames[-1] = frames[0]  # as the export writes a looping clip

    def write(options: PackOptions | None, layout: Layout | None) -> bytes:
        return clip_animation_glb(clip, FPS, options=options,
                                  layout=layout or plain_layout(clip.faces, clip.n_vertices))

    return Case(label, frames, write, clip.info().get("errors", {}), fit_s, source)


def model_case(label: str, path: Path, animation: str | None) -> Case:
    """A public model's animation sampled at 30 fps, fitted, exported."""
    from pdeanim.gltf.read import read_animated_poses

    src = path.read_bytes()
    return fitted_case(label, read_animated_poses(src, fps=FPS, animation=animation), src)


def sequence_case(name: str) -> Case:
    """A sequence of the compression benchmark (read in place), fitted, exported."""
    from pdeanim.posefiles import load_poses

    return fitted_case(name, load_poses(SEQUENCES / f"{name}.npz", fps=FPS))


def positions_only(glb: bytes) -> bytes:
    """The GLB without any NORMAL (base or target): what gltfpack welds by position (and UV) alone."""
    doc, binary = unpack_glb(glb)
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            prim["attributes"].pop("NORMAL", None)
            for target in prim.get("targets", []):
                target.pop("NORMAL", None)
    return pack_glb(doc, binary or b"")


def wire(blob: bytes) -> int:
    """Bytes on the wire: zstd -19 of the file."""
    import zstandard

    return len(zstandard.ZstdCompressor(level=WIRE_LEVEL).compress(blob))


def decoded_error(glb: bytes, frames: np.ndarray) -> tuple[float, float]:
    """(RMS, max) distance of a GLB's decoded frames from ``frames`` (K, V, 3), vertices matched by their
    trajectories (both writers weld and reorder)."""
    from scipy.spatial import cKDTree

    from pdeanim.gltf.read import read_animated_poses

    Y = read_animated_poses(glb, fps=FPS).vertices.astype(np.float64)
    X = frames.astype(np.float64)
    if len(Y) != len(X):
        raise RuntimeError(f"decoded {len(Y)} frames for {len(X)}")
    pick = np.unique(np.linspace(0, len(X) - 1, min(len(X), 8)).astype(int))

    def feat(P: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.moveaxis(P[pick], 0, 1).reshape(P.shape[1], -1))

    match = cKDTree(feat(Y)).query(feat(X), workers=1)[1]
    d = np.linalg.norm(Y[:, match] - X, axis=-1)
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def gltfpack(src: Path, flags: list[str], tmp: Path) -> bytes:
    """``gltfpack -i src`` with ``flags``."""
    out = tmp / "out.glb"
    subprocess.run([str(GLTFPACK), "-i", str(src), "-o", str(out), *flags], check=True, capture_output=True)
    return out.read_bytes()


@dataclass
class Packed:
    """One GLB: its flags, bytes, wire bytes and decoded error."""

    flags: str
    glb: bytes
    wire: int
    rms: float
    max: float


def pack(src: Path, flags: list[str], frames: np.ndarray, tmp: Path) -> Packed:
    glb = gltfpack(src, flags, tmp)
    return Packed(" ".join(flags), glb, wire(glb), *decoded_error(glb, frames))


def best_gltfpack(src: Path, frames: np.ndarray, rms: float, extra: list[str], tmp: Path) -> Packed | None:
    """gltfpack's smallest wire bytes over ``-cc -vp N`` with integer and float positions (``extra`` flags
    too) among the settings whose RMS error is at most ``rms``: for each, the fewest bits that meet it (bytes
    grow with bits), searched from below."""
    best = None
    for variant in ([], ["-vpf"]):
        for n in VP_BITS:
            got = pack(src, ["-cc", "-vp", str(n), *variant, *extra], frames, tmp)
            if got.rms <= rms:
                if best is None or got.wire < best.wire:
                    best = got
                break
    return best


def verdict(ratio: float) -> str:
    return "met" if ratio <= GOAL else "NOT met"


def rows(case: Case, args: argparse.Namespace) -> list[float]:
    """Print the rows of one case (plain and, with a source, look); the wire ratios to gltfpack's best."""
    extent = float(np.ptp(case.frames.reshape(-1, 3), axis=0).max())
    ratios = []
    for look in (False, True) if case.source is not None else (False,):
        layout = (lambda: gltf_layout(case.source)) if look else (lambda: None)
        start = time.perf_counter()
        ours = case.write(None, layout())
        build = time.perf_counter() - start
        ours_rms, ours_max = decoded_error(ours, case.frames)
        plain = positions_only(case.write(PackOptions(normals=False, **FLOAT32), layout()))
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / "in.glb"
            src.write_bytes(plain)
            default = pack(src, ["-cc"], case.frames, Path(tmp))
            best = best_gltfpack(src, case.frames, ours_rms, [], Path(tmp))
            khr = best_gltfpack(src, case.frames, ours_rms, ["-ce", "khr"], Path(tmp)) if args.khr else None
        fit_rms = case.fit.get("rms") or float("nan")
        kind = "look" if look else "plain"
        shape = f"{case.frames.shape[0]} x {case.frames.shape[1]}"
        print(f"{case.label:<21} {kind:<5} {shape:>11} fit rms {fit_rms / extent:.1e} ({case.fit_s:.0f} s)  "
              f"ours {len(ours):>9,} / wire {wire(ours):>9,}  quant rms {ours_rms / extent:.1e} "
              f"max {ours_max / extent:.1e} (x{ours_rms / fit_rms:.2f} of the fit's rms)  "
              f"build {build:.2f} s",
              flush=True)
        print(f"{'':<21} {'':<5} {'':>11} gltfpack -cc (default)  {len(default.glb):>9,} / wire "
              f"{default.wire:>9,}  rms {default.rms / extent:.1e}  "
              f"ours/gp wire {wire(ours) / default.wire:.2f}",
              flush=True)
        if best is None:
            print(f"{'':<21} {'':<5} {'':>11} gltfpack: no setting meets our error", flush=True)
            continue
        ratio, file_ratio = wire(ours) / best.wire, len(ours) / len(best.glb)
        ratios.append(ratio)
        print(f"{'':<21} {'':<5} {'':>11} gltfpack best ({best.flags}) {len(best.glb):>9,} / wire "
              f"{best.wire:>9,}  rms {best.rms / extent:.1e}  ours/gp wire {ratio:.2f} "
              f"(file {file_ratio:.2f})  goal <= {GOAL}x: {verdict(ratio)}", flush=True)
        if khr is not None:
            print(f"{'':<21} {'':<5} {'':>11} gltfpack KHR ({khr.flags}) {len(khr.glb):>9,} / wire "
                  f"{khr.wire:>9,}  rms {khr.rms / extent:.1e}  ours/gp wire {wire(ours) / khr.wire:.2f} "
                  f"(information: another extension)", flush=True)
        if args.validate:
            from pdeanim.gltf.validate import assert_glb_clean

            assert_glb_clean(ours, f"{case.label} {kind}")
            print(f"{'':<21} {'':<5} {'':>11} Khronos validator: 0 errors, 0 warnings", flush=True)
    return ratios


def main() -> int:
    """Print the rows of every case and the goal's verdict."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", nargs="*", default=[], help="sequences of ../shared/data/sequences too")
    ap.add_argument("--no-models", action="store_true", help="skip the quadruped and humanoid models")
    ap.add_argument("--khr", action="store_true", help="also gltfpack -ce khr (information)")
    ap.add_argument("--validate", action="store_true", help="also run the Khronos validator on our GLBs")
    args = ap.parse_args()
    if not GLTFPACK.exists():
        print(f"gltfpack not found at {GLTFPACK}: run script/setup (npm ci in tools/gltfpack)")
        return 2
    loaders: list[Callable[[], Case]] = []
    if not args.no_models:
        loaders += [lambda lab=label, s=src: model_case(lab, *s) for label, src in SOURCES.items()]
    loaders += [lambda n=name: sequence_case(n) for name in args.sequences]
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}  load average before: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("rms/max relative to the frames' largest extent; quant = what our export adds to the clip's "
          f"frames; wire = zstd -{WIRE_LEVEL}; gltfpack best = its smallest wire bytes with an RMS error "
          "<= ours")
    ratios = []
    for load in loaders:
        ratios += rows(load(), args)
        print(f"  (load average {' '.join(f'{x:.2f}' for x in os.getloadavg())})", flush=True)
    met = sum(r <= GOAL for r in ratios)
    print(f"goal: default animation GLB <= {GOAL}x gltfpack -cc (best settings, same frames and error, "
          f"wire): {met}/{len(ratios)} cases, worst {max(ratios, default=float('nan')):.2f}: "
          f"{'met' if ratios and met == len(ratios) else 'NOT met'}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
