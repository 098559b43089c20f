"""``pdeanim simulate MESH --frames N --out POSES.npz [scene options]``: XPBD poses of a mesh."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ..errors import ParameterError

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def floats(text: str, n: int | tuple[int, ...], name: str) -> list[float]:
    """Parse 'a,b,c' into n floats, or ParameterError naming the option."""
    counts = (n,) if isinstance(n, int) else n
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise ParameterError(f"{name} needs comma-separated numbers, got {text!r}") from exc
    if len(values) not in counts:
        raise ParameterError(f"{name} needs {' or '.join(map(str, counts))} numbers, got {text!r}")
    return values


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` sub-command."""
    p = subparsers.add_parser("simulate", help="XPBD poses of a mesh (pins, drivers, gravity, ground)",
                              description="Tetrahedralize MESH, simulate it with XPBD and write POSES.npz.")
    p.add_argument("mesh", help="surface mesh: .obj .ply .stl .off .glb .gltf")
    p.add_argument("--out", required=True, help="output POSES.npz")
    p.add_argument("--frames", type=int, default=100)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--duration", type=float, help="seconds spanned by the frames (overrides --fps)")
    p.add_argument("--scene", help="JSON file of scene parameters (flags given here override it)")
    p.add_argument("--gravity", help="X,Y,Z in m/s^2 (default 0,-9.81,0)")
    p.add_argument("--damping", type=float, help="velocity damping in 1/s (default 1)")
    p.add_argument("--young", type=float, help="Young's modulus in Pa (default: from the mesh's size, so "
                   "gravity compresses it by about 2%%: visible, stable motion whatever the units)")
    p.add_argument("--poisson", type=float, help="Poisson ratio in [0, 0.5) (default 0.3)")
    p.add_argument("--density", type=float, help="kg/m^3 (default 1000)")
    p.add_argument("--pin-box", action="append", default=[], metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX")
    p.add_argument("--pin-plane", action="append", default=[], metavar="PX,PY,PZ,NX,NY,NZ",
                   help="pin the side (x - p) . n <= 0")
    p.add_argument("--pin-indices", action="append", default=[], metavar="I,J,...", help="surface vertices")
    p.add_argument("--drive-box", action="append", default=[], metavar="XMIN,...,ZMAX")
    p.add_argument("--drive-plane", action="append", default=[], metavar="PX,PY,PZ,NX,NY,NZ")
    p.add_argument("--drive-indices", action="append", default=[], metavar="I,J,...")
    p.add_argument("--drive-rotate", metavar="AXIS,DEGREES", help="rotate the driven region (or the pins) "
                   "about AXIS (x, y, z or AX,AY,AZ) through its centroid, from 0 to DEGREES over the clip")
    p.add_argument("--drive-translate", metavar="X,Y,Z", help="translate the driven region by X,Y,Z over the "
                                                              "clip")
    p.add_argument("--drive-center", metavar="X,Y,Z", help="rotation center (default: region centroid)")
    p.add_argument("--relative", action="store_true", help="region points are fractions of the bounding box")
    p.add_argument(
        "--ground", metavar="Y|PX,PY,PZ,NX,NY,NZ", help="ground plane y = Y, or a point and normal"
    )
    p.add_argument("--friction", type=float, default=0.0, help="ground friction in [0, 1]")
    p.add_argument("--tets", type=int, help="target tet count (default 3000)")
    p.add_argument("--substeps", type=int, help="substeps per frame (default: automatic from the material)")
    p.add_argument("--iterations", type=int, help="solver iterations per substep (default 1)")
    p.add_argument("--threads", type=int, help="solver threads (default 1)")
    p.add_argument("--merge-seams", action="store_true", help="merge duplicate vertices before simulating")
    p.add_argument("--cache-dir", help="directory caching tetrahedralizations")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def regions(args: argparse.Namespace, prefix: str) -> list[dict]:
    """Region dicts from --PREFIX-box/-plane/-indices options."""
    rel = {"relative": True} if args.relative else {}
    out = [{"box": floats(b, 6, f"--{prefix}-box"), **rel} for b in getattr(args, f"{prefix}_box")]
    out += [{"plane": floats(b, 6, f"--{prefix}-plane"), **rel} for b in getattr(args, f"{prefix}_plane")]
    for text in getattr(args, f"{prefix}_indices"):
        try:
            out.append({"indices": [int(i) for i in text.split(",")]})
        except ValueError as exc:
            raise ParameterError(f"--{prefix}-indices needs integers, got {text!r}") from exc
    return out


def driver(args: argparse.Namespace, pins: list[dict]) -> list[dict]:
    """The driver list built from --drive-* options (applied to the drive regions, else to the pins)."""
    if not (args.drive_rotate or args.drive_translate):
        return []
    targets = regions(args, "drive") or pins
    if not targets:
        raise ParameterError("--drive-rotate/--drive-translate need a --drive-* or --pin-* region")
    key: dict = {"t": 1.0}
    if args.drive_rotate:
        axis, _, degrees = args.drive_rotate.rpartition(",")
        vec = list(AXES[axis.lower()]) if axis.lower() in AXES else floats(axis, 3, "--drive-rotate axis")
        key["rotate"] = vec + floats(degrees, 1, "--drive-rotate degrees")
    if args.drive_translate:
        key["translate"] = floats(args.drive_translate, 3, "--drive-translate")
    out = []
    for region in targets:
        d = {"region": region, "keyframes": [key]}
        if args.drive_center:
            d["center"] = floats(args.drive_center, 3, "--drive-center")
        out.append(d)
    return out


def scene_from_args(args: argparse.Namespace):
    """SceneParams from the --scene file and the flags."""
    from ..sim.scene import SceneParams

    d = json.loads(Path(args.scene).read_text()) if args.scene else {}
    d.update(frames=args.frames, fps=args.fps)
    optional = {
        "duration": args.duration,
        "damping": args.damping,
        "young": args.young,
        "poisson": args.poisson,
        "density": args.density,
        "target_tets": args.tets,
        "substeps": args.substeps,
        "iterations": args.iterations,
        "threads": args.threads,
    }
    d.update({k: v for k, v in optional.items() if v is not None})
    if args.gravity:
        d["gravity"] = floats(args.gravity, 3, "--gravity")
    pins = regions(args, "pin")
    d["pins"] = d.get("pins", []) + pins
    d["drivers"] = d.get("drivers", []) + driver(args, pins)
    if args.ground:
        g = floats(args.ground, (1, 6), "--ground")
        point, normal = ([0.0, g[0], 0.0], [0.0, 1.0, 0.0]) if len(g) == 1 else (g[:3], g[3:])
        d["ground"] = {"point": point, "normal": normal, "friction": args.friction}
    return SceneParams.from_dict(d)


def run(args: argparse.Namespace) -> int:
    """Load, simulate, save and print a one-screen summary."""
    from ..mesh.io import load_mesh
    from ..poses import save_poses
    from ..progress import cli_progress
    from ..sim.simulate import simulate_mesh

    scene = scene_from_args(args)
    mesh = load_mesh(args.mesh, merge_seams=args.merge_seams)

    progress = cli_progress("simulate", args.quiet)
    try:
        poses = simulate_mesh(mesh, scene, progress=progress,
                              cache_dir=Path(args.cache_dir) if args.cache_dir else None)
    finally:
        if progress is not None:
            progress.close()
    save_poses(args.out, poses)
    moved = np.linalg.norm(poses.vertices - poses.vertices[:1], axis=2).max()
    m = poses.meta
    print(f"wrote {args.out}: {poses.n_frames} frames x {poses.n_vertices} vertices, {m['tets']} tets, "
          f"{m['substeps']} substeps/frame{' (capped)' if m['substeps_capped'] else ''}, "
          f"tetrahedralize {m['tetrahedralize_seconds']} s, simulate {m['seconds']} s, "
          f"max displacement {moved:.4g} (bbox diagonal {mesh.diagonal():.4g}), young {m['young']:.4g} Pa"
          f"{' (from the mesh size)' if m['young_auto'] else ''}")
    for warning in m.get("warnings", []):
        print(f"pdeanim simulate: warning: {warning}", file=sys.stderr)
    return 0
