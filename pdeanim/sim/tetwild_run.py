"""Run pytetwild (fTetWild) on an .npz surface and write the tets: ``python -m pdeanim.sim.tetwild_run IN
OUT``.

Executed in a child process whose working directory is a private temporary directory, because fTetWild writes
``__tracked_surface.stl`` into the current directory and may abort the whole process on pathological input.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main(argv: list[str]) -> int:
    """Read vertices/faces/options from argv[0], tetrahedralize, write points/tets to argv[1]."""
    import pytetwild

    with np.load(argv[0], allow_pickle=False) as data:
        vertices = data["vertices"].astype(np.float64)
        faces = data["faces"].astype(np.int32)
        options = json.loads(str(data["options"]))
    points, tets = pytetwild.tetrahedralize(vertices, faces, quiet=True, **options)
    np.savez(argv[1], points=np.asarray(points, np.float64), tets=np.asarray(tets, np.int64))
    return 0


if __name__ == "__main__":  # pragma: no cover - exercised through a subprocess
    sys.exit(main(sys.argv[1:]))
