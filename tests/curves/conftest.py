"""Fixtures for the curve tests: the real meshes and a messy mesh with every awkward case at once."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh


def load_obj(path) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.load(path, process=False)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


@pytest.fixture(scope="session")
def spot(spot_path):
    return load_obj(spot_path)


@pytest.fixture(scope="session")
def bob(bob_path):
    return load_obj(bob_path)


@pytest.fixture(scope="session")
def morph(morph_sphere_path):
    d = np.load(morph_sphere_path)
    return d["vertices"], d["faces"].astype(np.int64)


@pytest.fixture(scope="session")
def messy() -> tuple[np.ndarray, np.ndarray]:
    """A grid split by a seam (duplicated vertices), a far triangle, a degenerate triangle, isolated
    points."""
    n = 8
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    grid = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(x.ravel())], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    faces = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    # seam: column y == 3 duplicated; faces on the side y >= 3 use the copies
    col = idx[:, 3]
    copy = np.arange(len(grid), len(grid) + n)
    verts = np.concatenate([grid, grid[col]])
    remap = np.arange(len(grid))
    remap[col] = copy
    right = (grid[faces].min(axis=1)[:, 1] >= 3)
    faces[right] = remap[faces[right]]
    k = len(verts)
    tri = np.array([[20.0, 0, 0], [21, 0, 0], [20, 1, 0]])
    degenerate = np.array([[30.0, 0, 0], [31, 0, 0], [32, 0, 0]])  # collinear, zero area
    isolated = np.array([[-5.0, -5, 0], [-5, 5, 0], [50, 50, 50]])
    verts = np.concatenate([verts, tri, degenerate, isolated])
    faces = np.concatenate([faces, [[k, k + 1, k + 2], [k + 3, k + 4, k + 5], [k + 3, k + 3, k + 4]]])
    return verts, faces.astype(np.int64)
