"""``pdeanim cyclic MESH --mode eel --out CLIP``: a loopable swim cycle of an elongated mesh.

A gait (``--mode walk``, run, trot, pace, canter, gallop, tripod or wave) on a skinned glTF/GLB instead makes
one locomotion cycle from the skeleton (legs found from it, or named with ``--legs``) and writes it as a
looping fitted clip (``--out CLIP``), a looping morph-target animation keeping the model's look (``--out
FILE.glb``) or poses (``--out POSES.npz``); the travel speed that keeps planted feet still is printed and
kept in the clip.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
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
                   "subcarangiform, carangiform, thunniform); a gait for a skinned glTF: walk, run (two "
                   "legs), walk, trot, pace, canter, gallop (four), tripod, wave (six or more)")
    p.add_argument("--out", required=True, help="output CLIP file (gaits: also FILE.glb or POSES.npz)")
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
    p.add_argument("--plot", help="also write a PNG of the body, its spine and a few frames (gaits: a strip "
                   "of frames and the footfall diagram) to this path")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="gait parameter (step_height, step_length, duty, height_right, lift_left, hip_bob, ...)",
    )
    p.add_argument("--legs", help="gaits: the foot joints, comma-separated (FOOT or TOP:FOOT), instead of "
                   "the legs found from the skeleton")
    p.add_argument("--forward", type=_vec, help="gaits: x,y,z facing direction instead of the one found")
    p.add_argument("--target-rel-rms", type=float, default=5e-4,
                   help="gaits, --out CLIP: the fit's RMS error target relative to the bounding-box diagonal")
    p.add_argument("--hip", help="gaits: the joint the body's bob moves (default: the one carrying the legs)")
    for side in ("right", "left"):
        p.add_argument(f"--{side}-foot", help=f"two-legged gaits: the {side} foot joint (default: found)")
    p.set_defaults(func=run)


def _load(path: str) -> Any:
    """The mesh, read and checked by :func:`pdeanim.mesh.io.load_mesh`."""
    from ..mesh.io import load_mesh

    return load_mesh(path)


def run(args: argparse.Namespace) -> int:
    """Build the clip, write it and print curves, sizes and the rest-pose distance."""
    from ..clip import load_clip, write_clip_file
    from ..cyclic.gaits import GAITS
    from ..cyclic.job import CyclicOptions, make_cyclic_clip

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


def _gait_options(args: argparse.Namespace) -> Any:
    """The CyclicOptions of a gait run from the command line."""
    from ..cyclic.job import CyclicOptions

    over: dict[str, Any] = {k: getattr(args, k) for k in ("frequency",) if getattr(args, k) is not None}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParameterError(f"--set expects KEY=VALUE, got {item!r}")
        over[key.strip()] = value.strip()
    return CyclicOptions.from_dict({
        "mode": args.mode, "overrides": over, "frames": args.frames, "legs": _legs(args),
        "forward": args.forward, "body_joint": args.hip, "target_rel_rms": args.target_rel_rms})


def _legs(args: argparse.Namespace) -> list[str] | None:
    """The feet named by --legs, or by --left-foot/--right-foot (the other foot found from the skeleton)."""
    if args.legs:
        if args.left_foot or args.right_foot:
            raise ParameterError("name the feet with --legs or with --left-foot/--right-foot, not both")
        return [x.strip() for x in args.legs.split(",") if x.strip()]
    if not (args.left_foot or args.right_foot):
        return None
    if args.left_foot and args.right_foot:
        return [args.left_foot, args.right_foot]
    from ..cyclic.bodyplan import plan_of
    from ..gltf.skin import load_skinned

    plan = plan_of(load_skinned(args.mesh), forward=args.forward)
    if plan.rows != 1:
        raise ParameterError("--left-foot/--right-foot name the feet of a two-legged character; use --legs")
    found = {leg.side: plan.skeleton.names[leg.foot] for leg in plan.legs}
    return [args.left_foot or found[1], args.right_foot or found[-1]]


def run_gait(args: argparse.Namespace) -> int:
    """Write one gait cycle of a skinned glTF as a looping clip, a looping GLB or poses; print the legs
    found, the travel speed and how still the planted feet are."""
    from ..clip import write_clip_file
    from ..cyclic.gaitclip import fit_gait_clip, gait_glb, solve_gait
    from ..poses import save_poses

    out = args.out.lower()
    if not out.endswith((".npz", ".glb", ".clip")):
        raise ParameterError("for gaits --out must be a .clip (fitted clip), .glb (animation) or .npz "
                             "(poses)")
    options = _gait_options(args)
    result = solve_gait(args.mesh, options.gait(), options.frames, options.legs, options.forward,
                        options.body_joint)
    r = result.report
    print("legs: " + ", ".join(f"{leg['name']} ({leg['foot']}, {leg['ik_bones']} bones)"
                               for leg in r["plan"]["legs"]))
    if out.endswith(".npz"):
        save_poses(args.out, result.poses)
    elif out.endswith(".glb"):
        with open(args.out, "wb") as fh:
            fh.write(gait_glb(args.mesh, result))
    else:
        parts = fit_gait_clip(result, options.target_rel_rms)
        write_clip_file(args.out, parts)
        c = parts.report["contact_clip"]
        print(f"clip: rel RMS {parts.report['rel_rms']:.3g}, " + _feet(c) + " in the clip")
    c, travel = r["contact"], r["travel"]
    print(f"{args.mode} cycle: {result.poses.n_frames} frames over {result.cycle.params.period:.4g} s, "
          f"travel {travel['speed']:.4g} units/s along {_fmt(travel['direction'])}, "
          + _feet(c) + f" -> {args.out}")
    if args.plot:
        _gait_plot(args.plot, args.mesh, result)
    return 0


def _feet(c: dict[str, Any]) -> str:
    """The honest foot figures: every sole vertex in every frame it is down."""
    return (f"soles slide at most {c['slide_max']:.4g} ({c['slide_max_rel']:.2%} of the leg) and sink "
            f"{c['sink_max_rel']:.2%} of the leg (all {sum(x['vertices'] for x in c['legs'])} vertices near "
            f"the ground, every frame they are down)")


def _fmt(v: list[float]) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def _gait_plot(path: str, mesh: str, result: Any) -> None:
    """Write the strip of frames and the footfall diagram of a gait."""
    from ..cyclic.gaitclip import skinned_offset
    from ..cyclic.gaitplots import face_colours, gait_strip_png
    from ..gltf.skin import load_skinned

    if not path.lower().endswith(".png"):
        raise ParameterError("--plot must name a .png file")
    skinned = load_skinned(mesh)
    start = skinned_offset(mesh)
    frames = result.poses.vertices[:, start:start + len(skinned.rest_vertices)]
    soles = [replace(s, vertices=s.vertices - start) for s in result.soles]
    gait_strip_png(path, frames, skinned.faces, face_colours(mesh, len(skinned.faces)), result.cycle,
                   title=f"{result.cycle.params.gait}", soles=soles)
    print(f"plot: {path}")
