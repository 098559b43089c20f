"""Shared fixtures: paths to the real meshes and sequences shipped in tests/data."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

# No per-example deadline anywhere: on a loaded, shared machine an example can take seconds, and the default
# 200 ms deadline then fails tests that are correct.
settings.register_profile("pdeanim", deadline=None)
settings.load_profile("pdeanim")

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def spot_path() -> Path:
    return DATA / "spot.obj"


@pytest.fixture(scope="session")
def bob_path() -> Path:
    return DATA / "bob.obj"


@pytest.fixture(scope="session")
def morph_sphere_path() -> Path:
    return DATA / "AnimatedMorphSphere.npz"
