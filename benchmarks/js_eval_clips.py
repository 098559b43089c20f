"""Write the 15k-vertex clips the JavaScript speed benchmark (js_eval_speed.mjs) evaluates.

A 150 x 100 torus (15,000 vertices, 150 ring curves) with a travelling bend over 40 frames, fitted with 4
segments in three motion modes (displacement, rigid, displacement looping), plus a cyclic-spine eel
(tests/data/fish_eel.obj subdivided twice: 23,042 vertices).
With --50k: a 250 x 200 torus (50,000 vertices, 250 ring curves, 8 segments; displacement and rigid) for
js_gpu_speed.mjs instead.
Run: .venv/bin/python benchmarks/js_eval_clips.py OUTDIR [--50k]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import trimesh  # noqa: E402
from model_common import ring_curves, torus_poses  # noqa: E402

from pdeanim.clip import write_clip_file  # noqa: E402
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip  # noqa: E402
from pdeanim.fit import FitOptions, fit_poses  # noqa: E402
from pdeanim.mesh.io import load_mesh  # noqa: E402

CASES = {"displacement": {}, "rigid": {"motion": "rigid"}, "loop": {"loop": True}}


def main(out: Path, big: bool = False) -> None:
    """Fit and write one CLIP file per case into out."""
    out.mkdir(parents=True, exist_ok=True)
    if big:
        poses = torus_poses(250, 200, 40)
        for name, opts in (("displacement", {}), ("rigid", {"motion": "rigid"})):
            parts = fit_poses(poses, FitOptions(segments=8, **opts), curves=ring_curves(250, 200))
            write_clip_file(out / f"torus50k-{name}.clip", parts)
            print(f"wrote {out / f'torus50k-{name}.clip'}")
        return
    poses = torus_poses(150, 100, 40)
    for name, opts in CASES.items():
        parts = fit_poses(poses, FitOptions(segments=4, **opts), curves=ring_curves(150, 100))
        write_clip_file(out / f"torus15k-{name}.clip", parts)
        print(f"wrote {out / f'torus15k-{name}.clip'}")
    eel = load_mesh(Path(__file__).parents[1] / "tests" / "data" / "fish_eel.obj")
    v, f = trimesh.remesh.subdivide(*trimesh.remesh.subdivide(eel.vertices, eel.faces))
    parts = make_cyclic_clip(trimesh.Trimesh(v, f, process=False), CyclicOptions(mode="eel"))
    write_clip_file(out / "eel23k-cyclic.clip", parts)
    print(f"wrote {out / 'eel23k-cyclic.clip'}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), "--50k" in sys.argv[2:])
