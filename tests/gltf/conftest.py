"""Fixtures of the glTF tests: real meshes and frames, and the validator (required: see script/setup)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh


@pytest.fixture(scope="session")
def spot(spot_path):
    mesh = trimesh.load(spot_path, process=False)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int64)


@pytest.fixture(scope="session")
def morph(morph_sphere_path):
    with np.load(morph_sphere_path) as d:
        return d["vertices"].astype(np.float32), d["faces"].astype(np.int64), d["times"].astype(np.float64)
