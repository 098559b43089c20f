"""``pdeanim fit POSES --out CLIP``: fit a dynamic-PDE clip to poses (.npz or animated .glb/.gltf).

Exit codes: 0 the target was met (or none was set, or ``--best-effort``); 3 the target was not met: the best
clip found is still written and stderr says what was achieved against what was asked (and why the search
stopped, e.g. the segment cap); 2 bad input; 4 out of memory (the message names the failed allocation, the
limit in force and what to lower); 1 other failures.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..errors import ParameterError
from .stream import LAYOUTS, add_window_arguments, check_window_arguments, streamed

EXIT_TARGET_NOT_MET = 3


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``fit`` sub-command."""
    p = subparsers.add_parser(
        "fit",
        help="fit a dynamic-PDE clip to poses",
        description="Fit curves of the mesh over time with the dynamic-PDE model.",
    )
    p.add_argument(
        "poses", help="POSES.npz (vertices (F,V,3), faces, optional times) or an animated .glb/.gltf"
    )
    p.add_argument("--out", required=True, help="output CLIP file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--target-rms", type=float, help="absolute RMS distance target")
    g.add_argument(
        "--target-rel-rms", type=float, help="RMS target relative to the first frame's bbox diagonal"
    )
    g.add_argument("--target-max", type=float, help="absolute max distance target")
    g.add_argument("--target-rel-max", type=float, help="max target relative to the bbox diagonal")
    g.add_argument("--segments", type=int, help="fixed number of time segments")
    p.add_argument("--param", choices=["chord", "paper"], default="chord", help="curve parameterisation")
    p.add_argument("--motion", choices=["displacement", "absolute", "rigid"], default="displacement",
                   help="fit displacement from the first frame (default), absolute positions, or per-curve "
                        "rigid motion plus a residual")
    p.add_argument("--loop", action="store_true", help="make the clip loop (last frame flows into the first)")
    p.add_argument("--fps", type=float, default=30.0, help="sampling rate for glTF input")
    p.add_argument(
        "--animation",
        metavar="NAME",
        help="glTF input: the animation to fit, by name or index "
        "(default: the first; the summary says which was used)",
    )
    p.add_argument("--max-segments", type=int,
                   help="cap on segments chosen for a target (default 4096, FitOptions.max_segments; "
                        "reaching it is reported)")
    p.add_argument("--time-model", choices=["auto", "pde", "spline"], default="auto",
                   help="time model of the curves: auto (default: per curve coordinate, the natural cubic "
                        "spline where it predicts and fits the motion as well as the paper's time solution, "
                        "else the paper's), pde (the paper's time solution alone: families with a constant "
                        "m per segment) or spline (every moving curve coordinate of an open clip on the "
                        "spline)")
    p.add_argument("--bones", default="auto", type=_bones_arg, metavar="auto|0|N",
                   help="bone layer under the curves (format 1.1): 'auto' (default) the bone count, none "
                        "included, whose clip is smallest; 0 none; N at most N bones from a skinning "
                        "decomposition. A skinned glTF keeps its own skeleton unless 0")
    p.add_argument("--best-effort", action="store_true",
                   help=f"exit 0 even when the target is not met (default: exit {EXIT_TARGET_NOT_MET})")
    p.add_argument("--pictures", metavar="DIR",
                   help="also write PNGs: per-vertex error at the worst frame and RMS/max error per frame")
    p.add_argument("--layout", choices=LAYOUTS, default="whole",
                   help="'whole' (default): the one-piece coefficients part (format 1.0/1.1); 'stream': "
                        "windows of time that decode on their own (format 1.2, docs/format.md §3.10), for "
                        "players that start before the whole clip has downloaded")
    add_window_arguments(p)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Load, fit, write the clip, print a short summary."""
    from ..clip import write_clip_file
    from ..fit import FitOptions, fit_poses, target_shortfall
    from ..fit.options import FitTolerances
    from ..posefiles import load_poses
    from ..progress import cli_progress

    if not args.fps > 0:
        raise ParameterError(f"--fps must be > 0, got {args.fps}")
    if args.layout == "stream":
        check_window_arguments(args)
    options = FitOptions(
        target_rms=args.target_rms,
        target_rel_rms=args.target_rel_rms,
        target_max=args.target_max,
        target_rel_max=args.target_rel_max,
        segments=args.segments,
        param_mode=args.param,
        motion=args.motion,
        loop=args.loop,
        **({} if args.max_segments is None else {"max_segments": args.max_segments}),
        best_effort=args.best_effort,
        time_model=args.time_model,
        bones=_bones_for(args),
    )
    start = time.perf_counter()
    # a long .npz is read a window of frames at a time from a file mapping (the frames stay in the page
    # cache, not in the fit's memory) where the fit would run in windows
    poses = load_poses(args.poses, fps=args.fps, animation=args.animation,
                       map_over=FitTolerances().window_fit_values)
    used = (poses.meta or {}).get("animation")
    if isinstance(used, dict):
        print(f"animation: {used.get('name') or '(unnamed)'} (index {used.get('index')})")
    check_memory_estimate(poses.n_frames, poses.n_vertices)
    skin = None
    if options.bones != 0 and Path(args.poses).suffix.lower() in (".glb", ".gltf"):
        from ..bones.gltfskin import skin_bones
        skin = skin_bones(args.poses, poses)
    progress = cli_progress("fit", args.quiet)
    try:
        parts = fit_poses(poses, options, progress=progress, skin=skin)
    except MemoryError as exc:
        raise out_of_memory_in_fit(exc, poses.n_frames, poses.n_vertices) from None
    finally:
        if progress is not None:
            progress.close()
    if args.layout == "stream":
        parts = streamed(parts, args)
    write_clip_file(args.out, parts)
    print(summary_text(parts.report, time.perf_counter() - start, args.out))
    if args.pictures:
        for path in write_pictures(poses, parts, args.pictures, Path(args.out).stem).values():
            print(f"picture -> {path}")
    shortfall = target_shortfall(parts.report)
    if shortfall:
        print(f"pdeanim fit: {shortfall} (the best clip found was written to {args.out})", file=sys.stderr)
        return 0 if args.best_effort else EXIT_TARGET_NOT_MET
    return 0


def _bones_arg(value: str) -> int | str:
    """--bones: "auto" or a bone count >= 0."""
    if value == "auto":
        return value
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--bones must be auto or a count >= 0, got {value!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"--bones must be auto or a count >= 0, got {value!r}")
    return n


def _bones_for(args: argparse.Namespace) -> int | str:
    """The bones option: "auto" becomes 0 where no bone layer can apply (a fixed segment count, motion
    other than displacement); an explicit count is passed on (and refused there with a reason)."""
    if args.bones == "auto" and (args.segments is not None or args.motion != "displacement"):
        return 0
    return args.bones


def _bones_line(b: dict | None) -> str:
    """How many bones the clip has, where they came from and the residual's share of the bytes."""
    if b and b.get("skipped"):
        return f"bones: none ({b['skipped']})"
    if not b or not b.get("n_bones"):
        tried = (b or {}).get("candidates")
        return "bones: none" + (f" (tried {', '.join(str(c['bones']) for c in tried)}: smallest without)"
                                if tried and len(tried) > 1 else "")
    line = (f"bones: {b['n_bones']} ({b.get('source')}), bone layer {b['bone_bytes']} bytes, residual curves "
            f"{b['residual_bytes']} bytes ({100 * b['residual_share']:.0f}% of the clip)")
    if b.get("skinning_rel_rms") is not None:
        line += f", skinning alone rel rms {b['skinning_rel_rms']:.3g}"
    return line


def out_of_memory_in_fit(exc: MemoryError, n_frames: int, n_vertices: int) -> Exception:
    """The OutOfMemoryError of a fit, with what a fit of this size is estimated to need."""
    from ..errors import OutOfMemoryError
    from ..outofmemory import out_of_memory

    if isinstance(exc, OutOfMemoryError):
        return exc
    return out_of_memory(exc, _fit_advice(n_frames, n_vertices))


def _fit_advice(n_frames: int, n_vertices: int) -> str:
    """What a fit of this size is estimated to need, and what would help."""
    from ..fit.budget import fit_memory_bytes
    from ..outofmemory import gib

    need = fit_memory_bytes(n_frames, n_vertices)
    return (f"a fit of {n_frames} frames x {n_vertices} vertices needs about {gib(need)} "
            "(pdeanim.fit.budget): fit fewer frames (a part of the poses) or a coarser mesh, or raise the "
            "limit (ulimit -v, or the container's memory)")


def check_memory_estimate(n_frames: int, n_vertices: int) -> None:
    """OutOfMemoryError (exit 4) before any fitting when the fit's estimate is over the memory limit in force
    (RLIMIT_AS, else the cgroup's), with the message an allocation failing later would give."""
    from ..errors import OutOfMemoryError
    from ..fit.budget import fit_memory_bytes
    from ..outofmemory import gib, memory_limit

    need, limit = fit_memory_bytes(n_frames, n_vertices), memory_limit()
    if limit is not None and need > limit[0]:
        raise OutOfMemoryError(f"out of memory: the estimated {gib(need)} of the fit is over the {limit[1]} "
                               f"of {gib(limit[0])} (refused before fitting); "
                               f"{_fit_advice(n_frames, n_vertices)}", need, limit[0])


def write_pictures(poses, parts, out_dir: str, name: str) -> dict:  # noqa: ANN001
    """Evaluate the clip at every source frame and draw where the fit struggles (pdeanim.pictures)."""
    import numpy as np

    from ..clip import load_clip
    from ..pictures import fit_error_pictures

    clip = load_clip(parts.topology, parts.coefficients)
    t = (poses.times - poses.times[0]) / max(poses.times[-1] - poses.times[0], 1e-12)
    fitted = clip.evaluate(np.asarray(t, np.float64))
    return fit_error_pictures(poses.vertices, fitted, poses.faces, poses.times, out_dir, name)


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g}"


def _time_models_line(counts: dict | None) -> str:
    """Which time model the curve coordinates use: "time models: spline 12, pde 3, linear 0"."""
    if not counts:
        return "time models: -"
    return ("time models (curve coordinates): natural spline {spline}, paper's pairs with a constant "
            "{pde}, paper's linear pair {linear}".format(**counts))


def summary_text(r: dict, seconds: float, out: str) -> str:
    """A few lines: achieved errors, target, sizes against raw, time."""
    s = r["sizes"]
    target = r.get("targets", {})
    met = r.get("target_met")
    lines = [
        f"fitted {r['frames']} frames x {r['vertices']} vertices with {r['curves']} curves, "
        f"{r['segments']} segments",
        f"rms {r['rms']:.4g} (rel {r['rel_rms']:.3g})  max {r['max']:.4g} (rel {r['rel_max']:.3g})  "
        f"KG {_fmt(r['kg'])}  spatial floor rel rms {r['floor_rel_rms']:.3g}",
        f"target rms={_fmt(target.get('rms'))} max={_fmt(target.get('max'))}: "
        + ("met" if met else "fixed segments" if met is None else "NOT met")
        + (" (the curves' spatial floor is above the target)" if r.get("floor_exceeds_target") else ""),
        f"bytes: topology {s['topology_bytes']}, coefficients {s['coefficients_bytes']}, "
        f"raw float32 {s['raw_float32_bytes']} (coefficients {100 * s['ratio_coefficients_to_raw']:.2f}% "
        f"of raw, total {100 * s['ratio_total_to_raw']:.2f}%), format {r.get('format_version')}"
        + (f", knots on {r['knot_rank']} shared time tracks" if r.get("knot_rank") else ""),
        _time_models_line(r.get("time_models")),
        f"time {seconds:.2f} s -> {out}",
        _bones_line(r.get("bones")),
    ]
    return "\n".join(lines)
