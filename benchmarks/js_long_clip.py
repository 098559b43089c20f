"""Make the long clip of the JS first-frame benchmark (benchmarks/js_first_frame.mjs --stream): 1,000 frames
on the ~33.7k-vertex spot, in the whole layout (1.0) and in the streamable one (1.2, feature "stream").

The topology, space constants and time constants come from a real fit of a short bending wave of the mesh
(9 frames; the spot of fit_scale_inputs.py, decimated to ~34k vertices); the 1,000 frames' knots are
*synthetic* (a travelling wave plus ``--noise``, each a share of the coefficient's own size, rounded as a
fit at 3e-3 of the diagonal would round them): a long fit costs minutes and GBs, and what the benchmark
measures (bytes per window, decoding, GPU tables, memory) depends on the layout and the sizes, not on how
the knots were chosen.

    .venv/bin/python benchmarks/js_long_clip.py [--frames 1000] [--vertices 34000] [--out-dir DIR]

Writes DIR/long<V>-<F>.clip (1.0) and DIR/long<V>-<F>.stream.clip (kept: a rerun reuses them). Default DIR:
/tmp/pdeanim-js-long.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from fit_scale_inputs import decimated_spot  # noqa: E402

DEFAULT_DIR = Path("/tmp/pdeanim-js-long")
FPS = 30.0


def short_fit(vertices: int):
    """ClipParts of a 9-frame bending wave of the subdivided spot (segments 2, time-pair items)."""
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.poses import make_poses

    rest, faces = decimated_spot(vertices)
    rest = np.asarray(rest, np.float64)
    axis = int(np.argmax(np.ptp(rest, axis=0)))
    u = (rest[:, axis] - rest[:, axis].min()) / np.ptp(rest[:, axis])
    frames = []
    for f in range(9):
        x = rest.copy()
        x[:, (axis + 1) % 3] += 0.05 * np.ptp(rest[:, axis]) * u * np.sin(2 * np.pi * (u - f / 8))
        frames.append(x)
    return fit_poses(
        make_poses(np.stack(frames), np.asarray(faces), np.arange(9) / FPS),
        FitOptions(segments=2, time_model="pde"),
    )


ZSTD_LEVEL = 3
"""zstd level of the long clip's arrays (the CLI's 19 takes many minutes on 240 MB of knot codes; the size is
set by the noise level anyway)."""


def long_parts(short, frames: int, noise: float, tolerance: float):
    """ClipParts of ``frames`` frames (one segment each) on the short fit's topology and constants."""
    from pdeanim import container
    from pdeanim.clip import ClipParts
    from pdeanim.model.clipformat import CoefficientData, decode_coefficients, encode_coefficients

    header, arrays = container.unpack(short.coefficients)
    C = int(header["n_curves"])
    src = decode_coefficients(header, arrays, C)
    S = frames - 1
    s = np.arange(S + 1)[:, None, None, None]
    phase = np.arange(C)[None, :, None, None] * 0.37 + np.arange(3)[None, None, :, None]
    # each coefficient moves by a share of its own size: a wave of 5% and the noise. (A share of the largest
    # knot, as before, moved the small high-order coefficients by 100x their size: every frame a ball of
    # triangles 1,500-4,800x the rest edge length, which software WebGL took tens of seconds to fill.)
    size = np.abs(src.knots[:1])
    rng = np.random.default_rng(7)
    knots = src.knots[:1] + size * (
        0.05 * np.sin(2 * np.pi * s / 60 + phase) + rng.normal(0.0, noise, (S + 1, *src.knots.shape[1:]))
    )
    data = CoefficientData(
        np.linspace(0.0, 1.0, S + 1),
        np.arange(S + 1) / FPS,
        np.repeat(src.family[:1], S, axis=0),
        np.repeat(np.asarray(src.m)[:1], S, axis=0),
        src.D,
        knots.astype(np.float32),
        src.motion,
        False,
        {"errors": {}},
        {},
        src.time_model,
    )
    coefficients = encode_coefficients(short.topology, data, tolerance, level=ZSTD_LEVEL, shared_basis=False)
    return ClipParts(short.topology, coefficients)


def make(out_dir: Path, vertices: int, frames: int, noise: float) -> tuple[Path, Path]:
    """The 1.0 and streamable CLIP files (made once per out_dir, size and length)."""
    from pdeanim.clip import read_clip_file, write_clip_file
    from pdeanim.model.streamlayout import to_stream

    out_dir.mkdir(parents=True, exist_ok=True)
    whole = out_dir / f"long{vertices}-{frames}.clip"
    stream = out_dir / f"long{vertices}-{frames}.stream.clip"
    if not whole.exists():
        cached = out_dir / f"short{vertices}.clip"
        if not cached.exists():
            t0 = time.perf_counter()
            write_clip_file(cached, short_fit(vertices))
            print(f"short fit: {time.perf_counter() - t0:.0f} s", flush=True)
        short = read_clip_file(cached)
        # knots rounded as a fit at a relative error of 3e-3 would round them (the target)
        from pdeanim.clip import load_clip

        rest = load_clip(short.topology, short.coefficients).evaluate(0.0)
        diagonal = float(np.linalg.norm(np.ptp(rest, axis=0)))
        t0 = time.perf_counter()
        parts = long_parts(short, frames, noise, 3e-3 * diagonal)
        mb = len(parts.coefficients) / 1e6
        print(f"long clip: {mb:.1f} MB of coefficients, {time.perf_counter() - t0:.0f} s", flush=True)
        write_clip_file(whole, parts)
    if not stream.exists():
        write_clip_file(stream, to_stream(read_clip_file(whole), level=ZSTD_LEVEL))
    return whole, stream


def main() -> int:
    """Make (or reuse) the clips and print their sizes."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=int, default=34_000)
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--noise", type=float, default=2e-2, help="knot noise, of each coefficient's magnitude")
    ap.add_argument("--out-dir", type=Path, default=DEFAULT_DIR)
    args = ap.parse_args()
    for path in make(args.out_dir, args.vertices, args.frames, args.noise):
        print(f"{path}: {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
