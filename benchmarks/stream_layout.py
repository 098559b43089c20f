"""The streamable layout (format 1.2, docs/format.md §3.10) against the one-piece layout of the same clips:
bytes, bytes before the first frame can play, conversion time, and how far its frames are from the one-piece
clip's.

    python benchmarks/stream_layout.py CLIP [CLIP ...] [--window-seconds 2,1,0.5] [--tangent-bits 4]

Per clip and window length: the coefficients' bytes in both layouts and their ratio (goal: at most
GOAL_RATIO at the default window length), the bytes a player needs before window 0 plays (prefix, header,
head and window 0) as a share of the whole, the conversion time (median of --runs), and the largest and RMS
difference of 201 frames from the one-piece clip's, relative to the bounding-box diagonal.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pdeanim.clip import load_clip, read_clip_file  # noqa: E402
from pdeanim.model.streamlayout import DEFAULT_TANGENT_BITS, DEFAULT_WINDOW_SECONDS, read_index, to_stream  # noqa: E402

GOAL_RATIO = 1.05
"""A clip in the streamable layout at the default window length is at most this many times its one-piece
coefficients (the issue's goal for a windowed clip against the one-piece one, applied to the layout)."""


def measure(path: Path, window_seconds: list[float], bits: int, runs: int) -> list[dict]:
    """One row per window length for the clip at ``path``."""
    parts = read_clip_file(path)
    whole = load_clip(parts.topology, parts.coefficients)
    t = np.linspace(0.0, 1.0, 201)
    want = whole.evaluate(t)
    diag = float(np.linalg.norm(np.ptp(want[0], axis=0))) or 1.0
    rows = []
    for seconds in window_seconds:
        times, stream = [], None
        for _ in range(runs):
            start = time.perf_counter()
            stream = to_stream(parts, window_seconds=seconds, tangent_bits=bits)
            times.append(time.perf_counter() - start)
        _, _, windows = read_index(stream.coefficients)
        got = load_clip(stream.topology, stream.coefficients).evaluate(t)
        diff = np.abs(got.astype(np.float64) - want)
        rows.append({"clip": path.stem, "frames": len(whole.frame_times), "vertices": whole.n_vertices,
                     "segments": len(whole.segment_t) - 1 if hasattr(whole, "segment_t") else None,
                     "seconds": seconds, "windows": len(windows), "whole": len(parts.coefficients),
                     "stream": len(stream.coefficients), "first": windows[0].end,
                     "convert_s": statistics.median(times), "max": float(diff.max()) / diag,
                     "rms": float(np.sqrt((diff**2).mean())) / diag})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clips", nargs="+", type=Path)
    ap.add_argument("--window-seconds", default=f"{DEFAULT_WINDOW_SECONDS:g},1,0.5")
    ap.add_argument("--tangent-bits", type=int, default=DEFAULT_TANGENT_BITS)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args(argv)
    seconds = [float(x) for x in args.window_seconds.split(",")]
    print(f"load average {os.getloadavg()[0]:.1f}, tangent bits {args.tangent_bits}, {args.runs} runs")
    print(f"{'clip':34} {'F':>5} {'V':>6} {'S':>5} {'win s':>6} {'W':>4} {'whole B':>10} {'stream B':>10} "
          f"{'ratio':>6} {'first B':>10} {'first %':>7} {'conv s':>7} {'max/diag':>9} {'rms/diag':>9}")
    verdicts = []
    for path in args.clips:
        for r in measure(path, seconds, args.tangent_bits, args.runs):
            ratio = r["stream"] / r["whole"]
            print(f"{r['clip'][:34]:34} {r['frames']:5d} {r['vertices']:6d} {r['segments']:5d} "
                  f"{r['seconds']:6g} {r['windows']:4d} {r['whole']:10d} {r['stream']:10d} {ratio:6.3f} "
                  f"{r['first']:10d} {100 * r['first'] / r['stream']:6.1f}% {r['convert_s']:7.2f} "
                  f"{r['max']:9.2e} {r['rms']:9.2e}")
            if r["seconds"] == DEFAULT_WINDOW_SECONDS:
                verdicts.append((r["clip"], ratio))
    for clip, ratio in verdicts:
        state = "met" if ratio <= GOAL_RATIO else "NOT met"
        print(f"goal: {clip} streamable at {DEFAULT_WINDOW_SECONDS:g} s windows <= {GOAL_RATIO}x the "
              f"one-piece coefficients: {ratio:.3f}x, {state}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
