"""``pdeanim stream CLIP --out OUT.clip``: a dynamic-PDE clip rewritten in the streamable layout (format 1.2,
feature "stream", docs/format.md §3.10): windows of time that decode on their own, in time order after a small
header and index, so a player starts on the first window while the rest downloads."""

from __future__ import annotations

import argparse
import math

from ..errors import ParameterError

LAYOUTS = ("whole", "stream")
"""Layouts of a written clip: ``whole`` the one-piece coefficients part (1.0/1.1), ``stream`` the
streamable one (1.2)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``stream`` sub-command."""
    p = subparsers.add_parser(
        "stream", help="rewrite a clip in the streamable layout (windows that decode on their own)",
        description="Rewrite a dynamic-PDE clip's coefficients as windows of time that decode on their own "
                    "(format 1.2, feature 'stream'): the same knots and time constants, the natural "
                    "spline's state stored at every window bound. Readers of format 1.0/1.1 refuse the "
                    "result with a message naming the feature.")
    p.add_argument("clip", metavar="CLIP", help="clip file written by `pdeanim fit`")
    p.add_argument("--out", required=True, metavar="OUT.clip", help="output CLIP file")
    add_window_arguments(p)
    p.set_defaults(func=run)


def add_window_arguments(p: argparse.ArgumentParser) -> None:
    """The window options shared by ``stream`` and ``fit --layout stream``."""
    from ..model.streamlayout import DEFAULT_TANGENT_BITS, DEFAULT_WINDOW_SECONDS, MAX_TANGENT_BITS

    p.add_argument("--window-seconds", type=float, default=DEFAULT_WINDOW_SECONDS, metavar="S",
                   help=f"source seconds per window of the streamable layout (default "
                        f"{DEFAULT_WINDOW_SECONDS:g}); a fit's own windows of frames are always window "
                        "bounds")
    p.add_argument("--max-window-segments", type=int, metavar="N",
                   help="at most N time segments per window of the streamable layout")
    p.add_argument("--tangent-bits", type=int, default=DEFAULT_TANGENT_BITS, metavar="B",
                   help=f"bits below the knot step of the spline's tangents stored at each window bound, "
                        f"0..{MAX_TANGENT_BITS} (default {DEFAULT_TANGENT_BITS}: 6 KB a bound on a 8k-vertex "
                        "clip, values within 1e-4 of the diagonal of the one-piece clip's; 16: float32 "
                        "rounding, about 4x the bytes)")


def check_window_arguments(args: argparse.Namespace) -> None:
    """Raise ParameterError for a bad window option (before any work: a long fit must not end in one)."""
    from ..model.streamlayout import MAX_TANGENT_BITS

    seconds = args.window_seconds
    if not (isinstance(seconds, float) and math.isfinite(seconds) and seconds > 0):
        raise ParameterError(f"--window-seconds must be a positive number, got {seconds}")
    if args.max_window_segments is not None and args.max_window_segments < 1:
        raise ParameterError(f"--max-window-segments must be at least 1, got {args.max_window_segments}")
    if not 0 <= args.tangent_bits <= MAX_TANGENT_BITS:
        raise ParameterError(f"--tangent-bits must lie in 0..{MAX_TANGENT_BITS}, got {args.tangent_bits}")


def streamed(parts, args: argparse.Namespace):  # noqa: ANN001, ANN201 - ClipParts in and out
    """``parts`` in the streamable layout with the window options of ``args``; ParameterError if bad."""
    from ..model.streamlayout import to_stream

    check_window_arguments(args)
    return to_stream(parts, window_seconds=args.window_seconds, max_window_segments=args.max_window_segments,
                     tangent_bits=args.tangent_bits)


def run(args: argparse.Namespace) -> int:
    """Read the clip, convert it, write it; prints the windows and sizes."""
    from ..clip import read_clip_file, write_clip_file
    from ..model.streamlayout import read_index

    check_window_arguments(args)
    parts = read_clip_file(args.clip)
    out = streamed(parts, args)
    write_clip_file(args.out, out)
    _, _, windows = read_index(out.coefficients)
    first = windows[0].end
    print(f"wrote {args.out} (streamable layout: {len(windows)} windows, coefficients "
          f"{len(out.coefficients)} bytes against {len(parts.coefficients)}; window 0 plays after the first "
          f"{first} bytes)")
    return 0
