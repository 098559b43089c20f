"""The compression benchmark's peers and protocol are the ones issue 22 states: a positions-only morph GLB
that the Khronos validator accepts and on which gltfpack can merge duplicate vertices, k found by bisection,
and held-out frames kept every 4th frame from 0 without forcing the last. Fast: tiny inputs."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

import peers_common  # noqa: E402
import peers_gltfpack  # noqa: E402
import peers_heldout  # noqa: E402
import peers_lowrank  # noqa: E402
from peers_synthetic import rig4_tube, tube  # noqa: E402

from pdeanim.gltf.glb import unpack_glb  # noqa: E402
from pdeanim.gltf.validate import assert_glb_clean  # noqa: E402


def seam_tube(frames: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A small moving tube whose first ring is stored twice (a UV-seam-like duplicate)."""
    rest, faces = tube(rings=4, around=6)
    rest = np.concatenate([rest, rest[:6]])
    half = len(faces) // 2  # tube() lists one triangle of every quad first: those use the copies
    faces[:half] = np.where(faces[:half] < 6, faces[:half] + len(rest) - 6, faces[:half])
    assert np.isin(np.arange(len(rest)), faces).all()  # both copies of the ring are used
    t = np.linspace(0, 1, frames)[:, None, None]
    X = rest[None] + t * np.array([0.0, 0.2, 0.0]) * rest[None, :, :1]
    return X, faces.astype(np.int32)


def test_the_gltfpack_input_is_a_valid_positions_only_morph_glb() -> None:
    X, faces = rig4_tube(frames=8)
    glb = peers_gltfpack.positions_morph_glb(X, faces)
    assert_glb_clean(glb, "positions-only morph GLB")
    doc, _ = unpack_glb(glb)
    prim = doc["meshes"][0]["primitives"][0]
    assert set(prim["attributes"]) == {"POSITION"}
    assert len(prim["targets"]) == len(X) - 1
    assert all(set(t) == {"POSITION"} for t in prim["targets"])


def test_gltfpack_merges_duplicate_vertices_and_is_scored_on_every_source_vertex(tmp_path: Path) -> None:
    assert peers_gltfpack.GLTFPACK_CLI.exists(), "run ./script/setup (npm ci in benchmarks/peers)"
    X, faces = seam_tube()
    src = tmp_path / "in.glb"
    src.write_bytes(peers_gltfpack.positions_morph_glb(X, faces))
    row = peers_gltfpack.pack_and_score(src, X, ["-cc", "-vp", "16", "-ce", "khr"], tmp_path, 120.0)
    assert row is not None
    assert row["decoded_vertices"] == X.shape[1] - 6
    assert row["rel_rms"] < 1e-4
    assert 0 < row["wire_bytes"] < row["file_bytes"] + 64


def test_smallest_meeting_finds_the_first_n_of_a_monotone_test() -> None:
    for first in (1, 2, 7, 40):
        assert peers_common.smallest_meeting(1, 40, lambda n, f=first: n >= f) == first
    assert peers_common.smallest_meeting(1, 40, lambda n: False) is None


def test_pca_peer_uses_the_smallest_k_that_meets_the_target() -> None:
    rng = np.random.default_rng(0)
    X, faces = rig4_tube(frames=24)
    X = X + 1e-5 * rng.standard_normal(X.shape)
    target = 3e-3
    rows = peers_lowrank.method_pca(X, faces, (target,), quick=True)
    best = min(rows, key=lambda r: r["wire_bytes"])
    assert best["rel_rms"] <= target
    m = peers_lowrank.PcaModel(X)
    assert m.rel_rms(best["k"] - 1, best["bits"], best["mean_bits"]) > target


def test_pca_peer_welds_seam_duplicates_and_ships_the_remap() -> None:
    X, faces = seam_tube()
    w = peers_common.WeldedInput(X, faces)
    assert w.merged and w.X.shape[1] == X.shape[1] - 6
    assert np.array_equal(w.expand(w.X), X)
    assert "remap" in w.arrays() and w.faces.max() < w.X.shape[1]
    rows = peers_lowrank.method_pca(X, faces, (3e-3,), quick=True)
    assert rows and all("welded" in r["setting"] and r["rel_rms"] <= 3e-3 for r in rows)


@pytest.mark.parametrize("frames", [48, 49, 53, 54])
def test_held_out_frames_are_every_fourth_from_zero_without_forcing_the_last(frames: int) -> None:
    keep, inside, left = peers_heldout.stated_split(frames)
    assert keep.tolist() == list(range(0, frames, 4))
    assert (frames - 1 in keep.tolist()) == ((frames - 1) % 4 == 0)
    assert sorted([*keep.tolist(), *left.tolist()]) == list(range(frames))
    assert inside.tolist() == [f for f in left.tolist() if f < keep[-1]]


def test_pca_peer_is_also_sized_for_the_max_error_yardstick() -> None:
    """A peer at its strongest on the stricter yardstick (rel-max <= 3x the target too): k is searched for
    that as well, not only for rel-RMS (issue 30)."""
    import peers_report

    rng = np.random.default_rng(1)
    X, faces = rig4_tube(frames=24)
    diag = float(np.linalg.norm(X[0].max(0) - X[0].min(0)))
    target = 3e-3
    X = X.copy()
    X[:, 7] += 12 * target * diag * rng.standard_normal((len(X), 3))  # one vertex on its own: a max error
    rows = peers_lowrank.method_pca(X, faces, (target,), quick=True)
    loose = peers_report.best(rows, "pca", target)
    strict = peers_report.best(rows, "pca", target, max_ratio=3.0)
    assert loose is not None and loose["rel_max"] > 3 * target
    assert strict is not None and strict["rel_max"] <= 3 * target and strict["rel_rms"] <= target
    assert strict["k"] > loose["k"]
