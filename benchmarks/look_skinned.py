"""The look at the default fit (issue 32): each textured skinned glTF of the repository fitted by
``pdeanim fit MODEL.glb --fps 10`` (the options a user gets: bones auto, so the file's skeleton, rel. RMS
3e-3), played on that glTF in a user's page (clients/js/test/browser/look.html: WebGPURenderer on WebGPU
and on its WebGL 2 fallback, WebGLRenderer) against three.js's own skinning and animation of the source at
the same times (t = 0, 0.5, 1 of its first animation), 256 x 256, no antialiasing. Printed per model and
renderer: the share of the model's pixels that differ by more than 40 levels (goal: under 1%), with the
clip's coefficient bytes (as stored and zstd -19) and its rel. RMS / max error at the fitted frames.

Models: the test suite's textured creature (tests/browser/models.py; flat: unwelded, no normals; smooth),
CesiumMan and the Fox (tests/gltf/data, see LICENSES.md there; the Fox's first animation, "Survey").

    .venv/bin/python benchmarks/look_skinned.py [--fit-args "--target-rel-rms 1e-3"] [--models fox,cesiumman]

Needs node, Chromium and clients/js's node_modules (script/setup). The load average is printed before and
after: the figures are pixels, not times, and do not depend on it.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
JS = ROOT / "clients" / "js"
GLTF = ROOT / "tests" / "gltf" / "data"
MODELS = ("creature-flat", "creature-smooth", "cesiumman", "fox")


def model_glb(name: str, work: Path) -> Path:
    """The GLB of a model, written into ``work`` where it is made here."""
    if name.startswith("creature"):
        from tests.browser.models import creature_glb

        path = work / f"{name}.glb"
        path.write_bytes(creature_glb(name.endswith("flat")))
        return path
    return GLTF / {"cesiumman": "CesiumMan.glb", "fox": "Fox.glb"}[name]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit-args", default="", help="extra `pdeanim fit` arguments (default: none)")
    ap.add_argument("--models", default=",".join(MODELS), help=f"subset of {','.join(MODELS)}")
    args = ap.parse_args()
    import numpy as np
    import zstandard

    from pdeanim.cli import main as pdeanim_main
    from pdeanim.clip import load_clip, read_clip_file
    from pdeanim.model.metrics import error_summary
    from pdeanim.posefiles import load_poses

    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}  load average before: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}  fit: pdeanim fit MODEL --fps 10 {args.fit_args}")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in args.models.split(","):
            glb, clip = model_glb(name, work), work / f"{name}.clip"
            argv = ["fit", str(glb), "--out", str(clip), "--fps", "10", "--quiet",
                    *shlex.split(args.fit_args)]
            if pdeanim_main(argv) != 0:
                print(f"{name}: the fit failed")
                return 1
            parts = read_clip_file(clip)
            frames = load_poses(glb, fps=10).vertices.astype(np.float64)
            decoded = load_clip(parts.topology, parts.coefficients)
            summary = error_summary(frames, decoded.evaluate(decoded.frame_t())[: len(frames)])
            wire = len(zstandard.ZstdCompressor(level=19).compress(parts.coefficients))
            proc = subprocess.run(["node", str(JS / "test" / "tools" / "look_page.mjs"), str(glb), str(clip)],
                                  cwd=JS, capture_output=True, text=True, timeout=600)
            if proc.returncode:
                print(f"{name}: look_page.mjs failed: {proc.stderr[-500:]}")
                return 1
            result = json.loads(proc.stdout.strip().splitlines()[-1])
            if result.get("skip") or result.get("errors"):
                print(f"{name}: {result.get('skip') or result['errors']}")
                return 1
            print(f"{name}: coefficients {len(parts.coefficients)} B ({wire} B zstd -19), rel. RMS "
                  f"{summary['rel_rms']:.2e}, rel. max {summary['rel_max']:.2e}")
            by: dict[str, list[str]] = {}
            for look in result["looks"]:
                by.setdefault(look["renderer"], []).append(f"{look['differ']:.2%}")
                worst = max(worst, look["differ"])
            for renderer, shares in by.items():
                print(f"  {renderer:16s} t=0/0.5/1: {' / '.join(shares)} of the model's pixels off by > 40 "
                      "levels")
    print(f"worst {worst:.2%}: {'met' if worst < 0.01 else 'NOT met'} (goal under 1%)  load average after: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
