"""Fixtures of the model tests: the morph-sphere poses (subsampled for speed) and fixed curves."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.model.simplecurves import simple_curves
from pdeanim.posefiles import load_poses
from pdeanim.poses import make_poses


@pytest.fixture(scope="session")
def morph_poses(morph_sphere_path):
    return load_poses(morph_sphere_path)


@pytest.fixture(scope="session")
def morph_small(morph_poses):
    """Every 3rd frame of AnimatedMorphSphere (72 frames x 1876 vertices)."""
    p = morph_poses
    return make_poses(p.vertices[::3], p.faces, p.times[::3])


@pytest.fixture(scope="session")
def short_curves(morph_poses):
    """Deterministic curves of at most 4 points (spatial floor ~0) that do not depend on other packages."""
    return simple_curves(morph_poses.vertices[0], max_points=4)


@pytest.fixture()
def rng():
    return np.random.default_rng(1234)
