"""Make the large clip the JS benchmarks use: spot subdivided to about 33.7k vertices, simulated with XPBD for
a few dozen frames (``pdeanim simulate``) and fitted (``pdeanim fit``), as a new user of the CLI would.

    .venv/bin/python benchmarks/js_large_clip.py [--vertices 33700] [--frames 36] [--out-dir DIR]

Writes DIR/spot<N>.obj, DIR/poses.npz and DIR/clip.clip (kept: a rerun reuses what is there) and prints the
clip's sizes. The default DIR is benchmarks/.cache/js-large (ignored by git).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from service_frames import obj_bytes, subdivided_spot  # noqa: E402

DEFAULT_DIR = ROOT / "benchmarks" / ".cache" / "js-large"


def make_clip(out_dir: Path, vertices: int = 33_700, frames: int = 36) -> Path:
    """The clip file (made once per out_dir and size)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh = out_dir / f"spot{vertices}.obj"
    poses = out_dir / f"poses{vertices}-{frames}.npz"
    clip = out_dir / f"clip{vertices}-{frames}.clip"
    cli = [str(Path(sys.executable).with_name("pdeanim"))]
    if not mesh.exists():
        mesh.write_bytes(obj_bytes(*subdivided_spot(vertices)))
    if not poses.exists():
        t0 = time.perf_counter()
        subprocess.run([*cli, "simulate", str(mesh), "--frames", str(frames), "--tets", "3000", "--quiet",
                        "--out", str(poses)], check=True, cwd=ROOT)
        print(f"simulate: {time.perf_counter() - t0:.0f} s")
    if not clip.exists():
        t0 = time.perf_counter()
        subprocess.run([*cli, "fit", str(poses), "--target-rel-rms", "0.002", "--quiet", "--out", str(clip)],
                       check=True, cwd=ROOT)
        print(f"fit: {time.perf_counter() - t0:.0f} s")
    return clip


def main() -> int:
    """Make (or reuse) the clip and print its sizes."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=int, default=33_700)
    ap.add_argument("--frames", type=int, default=36)
    ap.add_argument("--out-dir", type=Path, default=DEFAULT_DIR)
    args = ap.parse_args()
    clip = make_clip(args.out_dir, args.vertices, args.frames)
    from pdeanim.clip import load_clip_file

    c = load_clip_file(clip)
    print(f"{clip}: {clip.stat().st_size} bytes, {c.n_vertices} vertices")
    return 0


if __name__ == "__main__":
    sys.exit(main())
