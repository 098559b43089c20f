"""The skinning decomposition (pdeanim.bones): a bending tube made by linear blend skinning with three bones,
its seam vertices duplicated as a glTF export leaves them, is recovered to a small error."""

import numpy as np
import pytest

from pdeanim.bones.decompose import decompose
from pdeanim.bones.trajweld import weld_trajectories
from pdeanim.model.rigid import rodrigues


def bending_tube(frames: int = 12, rings: int = 25, around: int = 10, angles: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(F, V, 3) a tube along x bent at x = 1 and x = 2 (three bones, smooth weights near the joints), the
    first column of every ring duplicated (a seam), and the (V,) index of the vertex each one copies;
    ``angles`` (F,): the bend per frame (default a steady bend from 0 to 1)."""
    x = np.linspace(0.0, 3.0, rings)
    ang = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    ang = np.concatenate([ang, ang[:1]])  # the seam: the first column again
    X, A = np.meshgrid(x, ang, indexing="ij")
    rest = np.stack([X, 0.2 * np.cos(A), 0.2 * np.sin(A)], axis=-1).reshape(-1, 3)
    copies = np.arange(len(rest)).reshape(rings, around + 1)
    copies[:, -1] = copies[:, 0]
    w1 = np.clip((rest[:, 0] - 0.75) / 0.5, 0, 1)  # bone 1 from x = 0.75 .. 1.25
    w2 = np.clip((rest[:, 0] - 1.75) / 0.5, 0, 1)
    W = np.stack([1 - w1, w1 - w2, w2], axis=1)
    s = np.linspace(0.0, 1.0, frames) if angles is None else angles
    out = np.empty((frames, len(rest), 3))
    for f in range(frames):
        R1 = rodrigues(np.array([0.0, 0.0, 0.9 * s[f]]))
        R2 = rodrigues(np.array([0.3 * s[f], 0.0, 0.7 * s[f]])) @ R1
        j1, j2 = np.array([1.0, 0, 0]), np.array([2.0, 0, 0])
        p1 = (rest - j1) @ R1.T + j1
        j2m = R1 @ (j2 - j1) + j1
        p2 = (rest - j2) @ R2.T + j2m
        out[f] = W[:, :1] * rest + W[:, 1:2] * p1 + W[:, 2:] * p2
    return out.astype(np.float32), copies.reshape(-1)


def test_weld_merges_seam_duplicates():
    X, copies = bending_tube()
    w = weld_trajectories(X)
    assert w.n_points == len(np.unique(copies))
    assert np.array_equal(w.point_of, w.point_of[copies])
    assert np.array_equal(X[:, w.keep][:, w.point_of], X)


def test_decomposition_recovers_bending_tube():
    X, _ = bending_tube()
    w = weld_trajectories(X)
    diag = np.linalg.norm(np.ptp(X[0], axis=0))
    dec = decompose(X[:, w.keep], 3)
    assert dec.rms / diag < 2e-5  # 6.7e-6 measured
    assert dec.index.shape[1] <= 4
    assert np.all(dec.weight >= 0) and np.allclose(dec.weight.sum(axis=1), 1.0)
    assert np.allclose(dec.R[0], np.eye(3)) and np.allclose(dec.t[0], 0.0)
    again = decompose(X[:, w.keep], 3)
    assert np.array_equal(again.weight, dec.weight) and np.array_equal(again.R, dec.R)  # deterministic


def test_more_bones_fit_better():
    X, _ = bending_tube()
    one = decompose(X, 1)
    three = decompose(X, 3)
    assert three.rms < 0.2 * one.rms


@pytest.mark.parametrize("bones", [1, 5])
def test_unmoving_input_is_exact(bones):
    X = np.repeat(np.random.default_rng(0).normal(size=(1, 40, 3)), 4, axis=0)
    dec = decompose(X, bones)
    assert dec.rms < 1e-9


def test_sparse_weights_keep_fewer_influences_within_their_allowance():
    X, _ = bending_tube()
    X = X[:, weld_trajectories(X).keep]
    diag = np.linalg.norm(np.ptp(X[0], axis=0))
    dense = decompose(X, 3)
    allowed = 1e-3 * diag
    sparse = decompose(X, 3, sparse_rms=allowed)
    assert np.count_nonzero(sparse.weight) < 0.9 * np.count_nonzero(dense.weight)
    assert np.all(sparse.weight >= 0) and np.allclose(sparse.weight.sum(axis=1), 1.0)
    point_rms = np.sqrt(sparse.point_sq / len(X))
    assert point_rms.max() < 3 * allowed  # each point within its allowance (transforms refitted after)
    assert sparse.rms < 2 * allowed
