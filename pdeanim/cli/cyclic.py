"""``pdeanim cyclic MESH --mode eel --out CLIP``: a loopable swim cycle of an elongated mesh.

``--mode walk`` or ``--mode run`` on a skinned glTF/GLB instead writes one skeletal walk/run cycle as poses
(``--out POSES.npz``, to fit with ``pdeanim fit``) or as a looping morph-target animation (``--out
FILE.glb``).
"""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import ParameterError

SWIM_FLAGS = {"amplitude": float, "alpha": float, "phi": float, "frequency": float, "omega0": float,
              "omega1": float}


def _vec(text: str) -> list[float]:
    """Parse "x,y,z" into three floats (argparse type)."""
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected x,y,z, got {text!r}")
    try:
        return [float(p) for p in parts]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def register(subparsers: Any) -> None:
    """Add the ``cyclic`` sub-command."""
    p = subparsers.add_parser(
        "cyclic",
        help="a loopable swim cycle (PDE surface + spine wave) of an elongated mesh",
        description=__doc__,
    )
    p.add_argument("mesh", help="mesh file (OBJ, PLY, STL, OFF, GLB)")
    p.add_argument("--mode", default="eel", help="eel, trout, tropical, shark, dolphin (or anguilliform, "
                   "subcarangiform, carangiform, thunniform); walk or run for a skinned glTF")
    p.add_argument("--out", required=True, help="output CLIP file (walk/run: POSES.npz or FILE.glb)")
    p.add_argument("--curves", type=int, default=37, help="cross-section curves (rounded up to 3 B + 1)")
    p.add_argument("--points", type=int, default=32, help="samples per curve")
    p.add_argument("--modes", type=int, default=6, help="Fourier modes solved exactly (M)")
    p.add_argument("--frames", type=int, default=24, help="frames per cycle for export")
    p.add_argument("--head", type=_vec, help="x,y,z point near the head")
    p.add_argument("--tail", type=_vec, help="x,y,z point near the tail")
    p.add_argument("--lateral", type=_vec, help="x,y,z sideways direction of the swim wave")
    for name, kind in SWIM_FLAGS.items():
        p.add_argument(f"--{name}", type=kind, help=f"override the preset's {name}")
    p.add_argument("--wave", choices=["standing", "travelling"], help="standing (paper Eq. 11) or travelling")
    p.add_argument("--radial", choices=["rotate", "translate"], help="how points follow the bent spine")
    p.add_argument(
        "--direction", choices=["lateral", "vertical"], help="side to side (fish) or up and down (dolphin)"
    )
    p.add_argument("--plot", help="also write a PNG of the body, its spine and a few frames to this path")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="walk/run parameter (step_height, step_length, height_right, lift_left, hip_bob, ...)",
    )
    for joint in ("hip", "right-foot", "left-foot"):
        p.add_argument(
            f"--{joint}", help=f"walk/run: name of the {joint.replace('-', ' ')} joint (default: by name)"
        )
    p.set_defaults(func=run)


def _load(path: str) -> Any:
    """The mesh, read and checked by :func:`pdeanim.mesh.io.load_mesh`."""
    from ..mesh.io import load_mesh

    return load_mesh(path)


def run(args: argparse.Namespace) -> int:
    """Build the clip, write it and print curves, sizes and the rest-pose distance."""
    from ..clip import load_clip, write_clip_file
    from ..cyclic.job import CyclicOptions, make_cyclic_clip
    from ..cyclic.skeletal import GAITS

    if args.mode in GAITS:
        return run_gait(args)

    over = {
        k: getattr(args, k)
        for k in [*SWIM_FLAGS, "wave", "radial", "direction"]
        if getattr(args, k) is not None
    }
    options = CyclicOptions.from_dict(
        {
            "mode": args.mode,
            "overrides": over,
            "n_curves": args.curves,
            "points": args.points,
            "modes": args.modes,
            "frames": args.frames,
            "head": args.head,
            "tail": args.tail,
            "lateral": args.lateral,
        }
    )
    mesh = _load(args.mesh)
    parts = make_cyclic_clip(mesh, options)
    write_clip_file(args.out, parts)
    r = parts.report
    d = r["rest_distance"]
    print(f"curves: {r['curves']} ({r['patches']} patches, {r['points']} points, {r['modes']} modes)")
    print(
        f"bytes: coefficients {len(parts.coefficients)}, topology {len(parts.topology)}, "
        f"mesh {r['mesh_bytes']}"
    )
    print(
        f"rest-pose distance to the PDE surface: mean {d['mean']:.4g} ({d['rel_mean']:.2e} of the diagonal), "
        f"max {d['max']:.4g} ({d['rel_max']:.2e})"
    )
    print(
        f"swim: {r['swim']['mode']}, period {r['period']:.4g} s, {r['frames']} frames per cycle -> {args.out}"
    )
    if args.plot:
        _plot(args.plot, load_clip(parts.topology, parts.coefficients))
    return 0


def _plot(path: str, clip: Any) -> None:
    """Write the swim-frames picture of a clip."""
    import numpy as np

    from ..cyclic.plots import plot_swim_frames

    if not path.lower().endswith(".png"):
        raise ParameterError("--plot must name a .png file")
    plot_swim_frames(path, clip, np.linspace(0.0, 1.0, 7)[:-1])
    print(f"plot: {path}")


def run_gait(args: argparse.Namespace) -> int:
    """Write one walk/run cycle of a skinned glTF as POSES.npz or a looping GLB animation."""
    from ..cyclic.skeletal import StepParams, step_cycle
    from ..gltf.skin import load_skinned
    from ..poses import save_poses

    out = args.out.lower()
    if not out.endswith((".npz", ".glb")):
        raise ParameterError("for walk/run cycles --out must be a .npz (poses) or .glb (animation) file")
    over: dict[str, Any] = {k: getattr(args, k) for k in ("frequency",) if getattr(args, k) is not None}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParameterError(f"--set expects KEY=VALUE, got {item!r}")
        over[key.strip()] = (
            value.strip().lower() in ("1", "true", "yes") if key.strip() == "literal" else value
        )
    joints = {"hip": args.hip, "right_foot": args.right_foot, "left_foot": args.left_foot}
    poses = step_cycle(
        load_skinned(args.mesh), StepParams.preset(args.mode, **over), frames=args.frames, **joints
    )
    if out.endswith(".npz"):
        save_poses(args.out, poses)
    else:
        from ..gltf.write import animation_glb

        with open(args.out, "wb") as fh:
            fh.write(animation_glb(poses.vertices, poses.times, poses.faces, loop=True))
    print(f"{args.mode} cycle: {poses.vertices.shape[0]} frames over {poses.times[-1]:.4g} s, "
          f"{poses.vertices.shape[1]} vertices -> {args.out}")
    return 0
