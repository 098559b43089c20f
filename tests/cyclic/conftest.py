"""Fixtures of the cyclic tests: the generated fish meshes and a ready clip (built once per session)."""

from __future__ import annotations

import pytest

from pdeanim.clip import load_clip
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.mesh.io import load_mesh


@pytest.fixture(scope="session")
def trout_mesh(data_dir):
    return load_mesh(data_dir / "fish_trout.obj")


@pytest.fixture(scope="session")
def capsule_mesh(data_dir):
    return load_mesh(data_dir / "fish_capsule.obj")


@pytest.fixture(scope="session")
def trout_parts(trout_mesh):
    return make_cyclic_clip(trout_mesh, CyclicOptions(mode="trout"))


@pytest.fixture(scope="session")
def trout_clip(trout_parts):
    return load_clip(trout_parts.topology, trout_parts.coefficients)
