"""A stray unreferenced vertex far from an elongated mesh must not stretch the body axis of a swim cycle."""

from __future__ import annotations

import numpy as np

from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.mesh.io import load_mesh


def test_unreferenced_vertex_does_not_break_cyclic(data_dir) -> None:
    """fish_eel.obj plus one unused vertex beyond its head: same clip vertex count, finite rest distance."""
    mesh = load_mesh(data_dir / "fish_eel.obj")
    lo, hi = mesh.bbox()
    mesh.vertices = np.vstack([mesh.vertices, hi + 0.5 * (hi - lo)])
    parts = make_cyclic_clip(mesh, CyclicOptions.from_dict({"mode": "eel", "frames": 8}))
    assert parts.report["curves"] >= 3
    assert np.isfinite(parts.report["rest_distance"]["mean"])
    assert parts.report["body_length"] < 1.01 * float(np.ptp(mesh.vertices[:-1, 0]))
