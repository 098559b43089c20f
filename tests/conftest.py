"""Shared fixtures: paths to the real meshes and sequences shipped in tests/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# moto's dummy S3 credentials, set before any test starts a process: the upload validator's forkserver
# (started once per test process, by whichever test uploads first) and the children it forks keep the
# environment they started with, so credentials set later by the S3 fixture would not reach them
for _name, _value in {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing",
                      "AWS_DEFAULT_REGION": "us-east-1"}.items():
    os.environ.setdefault(_name, _value)

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
