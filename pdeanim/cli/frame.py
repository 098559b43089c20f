"""``pdeanim frame CLIP --t T[,T2...|all] --out FILE.npz|FILE.glb``: evaluate a clip at normalised times."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

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
    """Evaluate and write vertices in the original order (a .npz streamed a block of frames at a time)."""
    from ..clip import open_clip, read_clip_file

    parts = read_clip_file(args.clip)
    clip = open_clip(parts.topology, parts.coefficients, DECODE_BYTES)
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
    if suffix == ".glb":
        if len(times) != 1:
            raise ParameterError("a .glb output takes a single --t")
        from ..gltf.write import frame_glb

        out.write_bytes(frame_glb(clip.evaluate(times)[0], clip.faces))
    elif scalar:
        with open(out, "wb") as fh:
            np.savez(fh, vertices=clip.evaluate(times)[0], faces=clip.faces, t=times)
    else:
        write_frames_npz(out, clip, times)
    print(f"wrote {len(times)} frame(s) of {clip.n_vertices} vertices -> {out}")
    return 0


DECODE_BYTES = 64 << 20
"""A clip whose decoding would take more than this is evaluated a block of curves at a time
(pdeanim.model.clipblocks): the same positions in memory bounded by the block."""
FRAME_BLOCK_BYTES = 16 << 20
"""Frames of a whole decoded clip are evaluated and written this many bytes at a time."""


def write_frames_npz(path: Path, clip: Any, times: np.ndarray) -> None:
    """The .npz of ``np.savez(vertices=clip.evaluate(times), faces=..., t=times)``, written a block of frames
    at a time into its zip entry, without holding the frames (a clip evaluated by blocks of curves gathers
    each block of frames from its scratch file: :meth:`BlockedClip.frame_chunks`)."""
    import zipfile

    from numpy.lib import format as npy

    shape = (len(times), clip.n_vertices, 3)
    header = {"descr": npy.dtype_to_descr(np.dtype(np.float32)), "fortran_order": False, "shape": shape}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
        with zf.open("vertices.npy", "w", force_zip64=True) as entry:
            npy.write_array_header_1_0(entry, header)
            step = max(1, FRAME_BLOCK_BYTES // max(1, clip.n_vertices * 12))
            if hasattr(clip, "frame_chunks"):  # evaluated by blocks of curves
                for frames in clip.frame_chunks(times, step, scratch=path.parent):
                    entry.write(frames.tobytes())
            else:
                for a in range(0, len(times), step):
                    entry.write(np.ascontiguousarray(clip.evaluate(times[a:a + step]), np.float32).tobytes())
        for name, value in (("faces", clip.faces), ("t", times)):
            with zf.open(f"{name}.npy", "w", force_zip64=True) as entry:
                npy.write_array(entry, np.asanyarray(value))
