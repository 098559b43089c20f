"""``pdeanim frame CLIP --t T[,T2...|all] --out FILE.npz|FILE.glb``: evaluate a clip at normalised times."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import ParameterError


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``frame`` sub-command."""
    p = subparsers.add_parser(
        "frame",
        help="evaluate a clip at times t in [0, 1]",
        description="t in [0, 1] maps linearly onto the clip's first..last frame times.",
    )
    p.add_argument("clip", help="CLIP file")
    p.add_argument("--t", required=True, help="a time, a comma-separated list, or 'all' (every source frame)")
    p.add_argument("--out", required=True, help="FILE.npz (vertices, faces, t) or FILE.glb (single t)")
    p.set_defaults(func=run)


def parse_times(text: str, frame_t: np.ndarray) -> tuple[np.ndarray, bool]:
    """(times (K,), scalar?) from the --t argument; raises ParameterError."""
    if text.strip().lower() == "all":
        return np.asarray(frame_t, np.float64), False
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise ParameterError(f"--t must be numbers separated by commas or 'all', got {text!r}") from exc
    if not values or not all(np.isfinite(values)):
        raise ParameterError(f"--t needs at least one finite time, got {text!r}")
    return np.asarray(values), len(values) == 1 and "," not in text


def run(args: argparse.Namespace) -> int:
    """Evaluate and write vertices in the original order."""
    from ..clip import load_clip_file

    clip = load_clip_file(args.clip)
    ft = clip.frame_times
    frame_t = (ft - ft[0]) / (ft[-1] - ft[0]) if len(ft) > 1 and ft[-1] > ft[0] else np.zeros(len(ft))
    times, scalar = parse_times(args.t, frame_t)
    if not clip.looping and ((times < 0.0) | (times > 1.0)).any():  # as the HTTP API: 422 t_out_of_range
        bad = times[(times < 0.0) | (times > 1.0)][0]
        raise ParameterError(f"--t must lie in [0, 1] for this clip (it does not loop), got {bad:g}")
    out = Path(args.out)
    suffix = out.suffix.lower()
    if suffix not in (".npz", ".glb"):
        raise ParameterError(f"--out must end in .npz or .glb, got {out.name!r}")
    frames = clip.evaluate(times)
    if suffix == ".glb":
        if len(times) != 1:
            raise ParameterError("a .glb output takes a single --t")
        from ..gltf.write import frame_glb

        out.write_bytes(frame_glb(frames[0], clip.faces))
    else:
        with open(out, "wb") as fh:
            np.savez(fh, vertices=frames[0] if scalar else frames, faces=clip.faces, t=times)
    print(f"wrote {len(times)} frame(s) of {clip.n_vertices} vertices -> {out}")
    return 0
