"""``pdeanim export CLIP --fps 30 --out FILE.glb [--quantize]``: the clip as a morph-target animation."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..clip import load_clip_file
from ..gltf.clipexport import clip_animation_glb
from ..progress import cli_progress


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` sub-command."""
    p = subparsers.add_parser("export", help="write a clip as an animated GLB (morph targets + weights animation)",
                              description="Sample a clip at --fps over its duration (last frame included; "
                                          "looping clips loop seamlessly) and write a glTF 2.0 binary file.")
    p.add_argument("clip", metavar="CLIP", help="clip file written by `pdeanim fit` or `pdeanim cyclic`")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second of the animation (default 30)")
    p.add_argument("--out", required=True, metavar="FILE.glb", help="output GLB path")
    p.add_argument("--quantize", action="store_true",
                   help="store positions as 16-bit integers (KHR_mesh_quantization), about 40%% smaller")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Load the clip, sample it and write the GLB; prints what was written."""
    clip = load_clip_file(args.clip)
    progress = cli_progress("export", args.quiet)
    try:
        glb = clip_animation_glb(clip, args.fps, quantize=args.quantize, progress=progress)
    finally:
        if progress is not None:
            progress.close()
    out = Path(args.out)
    out.write_bytes(glb)
    print(f"wrote {out} ({len(glb)} bytes, {clip.n_vertices} vertices, {len(clip.frame_times)} source frames, "
          f"{args.fps:g} fps{', looping' if clip.looping else ''}{', quantised' if args.quantize else ''})")
    return 0
