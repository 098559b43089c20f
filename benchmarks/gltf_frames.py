"""Frame GLB writing time in the API's frame route: the plain writer (``FrameGlb``) against the one that keeps
the source's look (``LayoutFrames``: UVs of an OBJ, or a glTF's primitives and materials), per frame, for
bob.obj (5.3k vertices, UVs) and spot.obj (2.9k vertices, UVs). Medians of ``--repeats`` calls; the load
average is printed because the machine may be shared.

    .venv/bin/python benchmarks/gltf_frames.py [--repeats 200]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pdeanim.gltf.compact import LayoutFrames  # noqa: E402
from pdeanim.gltf.layout import source_layout  # noqa: E402
from pdeanim.gltf.write import FrameGlb  # noqa: E402
from pdeanim.mesh.io import load_mesh  # noqa: E402


def median_ms(fn, positions: np.ndarray, repeats: int) -> float:  # noqa: ANN001
    """Median milliseconds of ``fn(positions)``."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn(positions)
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def main() -> int:
    """Print one row per mesh: vertices, plain ms, look-keeping ms, and the layout kind."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'mesh':<10} {'vertices':>8} {'layout':>6} {'plain ms':>9} {'look ms':>8}")
    for name in ("bob.obj", "spot.obj"):
        path = ROOT / "tests" / "data" / name
        mesh = load_mesh(path)
        layout = source_layout(path.read_bytes(), name, mesh.faces, len(mesh.vertices))
        positions = (mesh.vertices * 1.01).astype(np.float32)
        plain = median_ms(FrameGlb(mesh.faces, len(mesh.vertices)), positions, args.repeats)
        look = median_ms(LayoutFrames(layout), positions, args.repeats)
        print(f"{name:<10} {len(mesh.vertices):>8} {layout.source:>6} {plain:>9.2f} {look:>8.2f}", flush=True)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
