"""Welded animation GLBs: vertices whose written data are equal in every frame become one (a flat-shaded,
unwelded quadruped's 1,728 corners weld to its 290 distinct vertices), vertices that meet at rest but move
apart stay apart, a source without normals stays without (flat-shaded) and one with normals keeps them; every
output is validator-clean and shows each clip vertex where the clip puts it (via ``_PDEANIM_VERTEX``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdeanim.cli import main
from pdeanim.clip import write_clip_file
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.gltf.compact import PackOptions, layout_animation_glb
from pdeanim.gltf.document import load_document
from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.layout import gltf_layout, plain_layout
from pdeanim.gltf.read import read_animated_poses, read_static_mesh
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.weld import VERTEX_MAP, flat_shaded, row_bytes, weld, weld_labels

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def fox():
    """The Fox sample (flat-shaded, no normals, 1,728 unwelded corners) and 12 frames of its run."""
    src = (DATA / "Fox.glb").read_bytes()
    poses = read_animated_poses(src, fps=30, animation="Run")
    return src, poses.vertices[:12].astype(np.float32), poses.faces.astype(np.int64)


def animation(layout, frames, **options) -> bytes:
    k = len(frames)
    return layout_animation_glb(layout, frames, np.arange(k, dtype=np.float32) / 30, np.arange(k), k,
                                options=PackOptions(**options))


def primitives(glb: bytes) -> list[dict]:
    doc, _ = unpack_glb(glb)
    return [p for m in doc["meshes"] for p in m["primitives"]]


def distinct(frames: np.ndarray, *extra: np.ndarray) -> int:
    """Vertices with distinct positions in every frame (and extra per-vertex data)."""
    return len(np.unique(row_bytes(frames.transpose(1, 0, 2), *extra), axis=0))


def step_of(frames: np.ndarray) -> float:
    return float(np.ptp(frames.reshape(-1, 3), axis=0).max()) / (2**14 - 1)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 12), st.integers(1, 30), st.integers(0, 2**31 - 1))
def test_weld_keeps_every_corner_and_merges_only_equal_rows(points, triangles, seed):
    """Corners pick from a few points; some points have a twin at the same rest position that moves
    differently (a crack): the weld merges exactly the equal rows and every corner keeps its data."""
    rng = np.random.default_rng(seed)
    rest = rng.integers(0, 4, (points, 3)).astype(np.int16)
    motion = rng.integers(-3, 3, (points, 4, 3)).astype(np.int16)
    twin = rng.random(points) < 0.3
    rest = np.concatenate([rest, rest[twin]])
    motion = np.concatenate([motion, motion[twin] + 1])  # same rest, different motion
    faces = rng.integers(0, len(rest), (triangles, 3))
    corners = faces.reshape(-1)  # an unwelded copy: one vertex per corner
    rest_c, motion_c = rest[corners], motion[corners]
    labels = weld_labels(row_bytes(rest_c), lambda idx: row_bytes(motion_c[idx]))
    welded = weld(labels, np.arange(len(corners)).reshape(-1, 3))
    data = np.concatenate([rest_c[:, None], motion_c], axis=1)  # (corners, 5, 3)
    used = np.unique(row_bytes(data), axis=0)
    assert len(welded.keep) == len(used)
    tris = np.arange(len(corners)).reshape(-1, 3)
    solid = [len({tuple(data[c].ravel()) for c in tri}) == 3 for tri in tris]
    want = data.reshape(-1, 3, 5, 3)[np.asarray(solid)] if any(solid) else data.reshape(-1, 3, 5, 3)
    np.testing.assert_array_equal(data[welded.keep][welded.faces], want)  # triangles kept in order


def test_flat_shaded_tells_facets_from_smooth_surfaces(spot):
    v, f = spot
    assert not flat_shaded(v, f)  # a smooth surface
    assert flat_shaded(v[f.reshape(-1)], np.arange(3 * len(f)).reshape(-1, 3))  # its triangle soup
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    shared = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    assert not flat_shaded(corners, shared)  # 8 shared corners: smooth normals round the cube
    split = np.arange(24).reshape(6, 4)  # 4 own corners per side: its two triangles are coplanar
    split_pos = corners[np.array(quads).reshape(-1)]
    split_faces = np.array([t for a, b, c, d in split for t in ((a, b, c), (a, c, d))])
    assert flat_shaded(split_pos, split_faces)
    assert not flat_shaded(v, np.zeros((0, 3), np.int64))


def test_flat_unwelded_quadruped_welds_and_has_no_normals(fox):
    src, frames, faces = fox
    k, n = frames.shape[:2]
    glb = animation(plain_layout(faces, n), frames)
    (prim,) = primitives(glb)
    assert "NORMAL" not in prim["attributes"] and all("NORMAL" not in t for t in prim["targets"])
    gd = load_document(glb)
    clip_vertex = gd.accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64)
    assert len(clip_vertex) == distinct(frames) == 290  # 1,728 corners, 290 distinct vertices
    back = read_animated_poses(glb, fps=30)
    assert back.vertices.shape == (k, 290, 3)
    np.testing.assert_allclose(back.vertices, frames[:, clip_vertex], atol=2 * step_of(frames))
    # every clip triangle is drawn: the same triangles of clip vertices, up to welded twins
    out = clip_vertex[gd.accessor(prim["indices"]).reshape(-1, 3).astype(np.int64)]
    key = np.unique(row_bytes(frames.transpose(1, 0, 2)), axis=0, return_inverse=True)[1].reshape(-1)
    assert {tuple(sorted(t)) for t in key[out]} == {tuple(sorted(t)) for t in key[faces]}
    unwelded = animation(plain_layout(faces, n), frames, weld=False)
    assert len(glb) < 0.3 * len(unwelded) and "NORMAL" not in primitives(unwelded)[0]["attributes"]
    assert_clean(validate_many([glb])[0], "welded flat quadruped")


def test_look_of_a_source_without_normals_welds_by_position_and_uv(fox):
    src, frames, _ = fox
    glb = animation(gltf_layout(src), frames)
    (prim,) = primitives(glb)
    assert "NORMAL" not in prim["attributes"]  # flat-shaded like the source
    gd, sd = load_document(glb), load_document(src)
    source_uv = sd.accessor(sd.doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"])
    clip_vertex = gd.accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64)
    assert len(clip_vertex) == distinct(frames, source_uv) == 434  # UV seams stay split
    np.testing.assert_array_equal(gd.accessor(prim["attributes"]["TEXCOORD_0"]), source_uv[clip_vertex])
    image = gd.view_bytes(gd.doc["images"][0]["bufferView"])
    assert image == sd.view_bytes(sd.doc["images"][0]["bufferView"])
    assert gd.doc["materials"] == sd.doc["materials"] and "skins" not in gd.doc
    back = read_animated_poses(glb, fps=30)
    np.testing.assert_allclose(back.vertices, frames[:, clip_vertex], atol=2 * step_of(frames))
    assert_clean(validate_many([glb])[0], "welded quadruped with its look")


def test_vertices_that_meet_at_rest_but_move_apart_stay_apart(fox):
    """gltfpack welds on the rest attributes only; here the fox's right half tears off its left along the
    mid-plane: corners on the seam meet at rest but move apart, so they must stay separate vertices."""
    _, frames, faces = fox
    rest = frames[0]
    left = np.zeros(len(rest), bool)
    centre = (rest[faces].mean(axis=1)[:, 0] < 0)  # triangles left of x = 0 move left
    left[faces[centre].reshape(-1)] = True
    torn = frames.copy()
    torn[:, left, 0] -= np.linspace(0, 5, len(frames))[:, None]
    glb = animation(plain_layout(faces, len(rest)), torn)
    (prim,) = primitives(glb)
    count = load_document(glb).accessor(prim["attributes"]["POSITION"]).shape[0]
    assert count == distinct(torn) > distinct(frames)  # the seam's corners are split in two
    assert distinct(torn[:1]) == distinct(frames[:1])  # ... though they meet at rest
    back = read_animated_poses(glb, fps=30)
    clip_vertex = load_document(glb).accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64)
    np.testing.assert_allclose(back.vertices, torn[:, clip_vertex], atol=2 * step_of(torn))


def test_smooth_source_keeps_normals_and_normal_targets():
    """The humanoid sample has normals: the export keeps smooth normals and their per-frame deltas, welds
    corners whose position, normal and UV agree in every frame, and the float32 layout welds the same."""
    src = (DATA / "CesiumMan.glb").read_bytes()
    poses = read_animated_poses(src, fps=10)
    frames = poses.vertices[:6].astype(np.float32)
    for options in ({}, {"quantize": False, "compress": False}):
        glb = animation(gltf_layout(src), frames, **options)
        (prim,) = primitives(glb)
        assert "NORMAL" in prim["attributes"] and all("NORMAL" in t for t in prim["targets"])
        gd = load_document(glb)
        assert gd.accessor(prim["attributes"]["POSITION"]).shape[0] < len(read_static_mesh(src)[0])
        clip_vertex = gd.accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64)
        np.testing.assert_allclose(read_animated_poses(glb, fps=30).vertices, frames[:, clip_vertex],
                                   atol=2 * step_of(frames))
        assert_clean(validate_many([glb])[0], f"humanoid with normals {options}")


def test_cli_export_welds_by_default(fox, tmp_path, capsys):
    src, frames, faces = fox
    parts = fit_poses(read_animated_poses(src, fps=30, animation="Run"), FitOptions(segments=4))
    clip_path, out = tmp_path / "fox.clip", tmp_path / "fox.glb"
    write_clip_file(clip_path, parts)
    assert main(["export", str(clip_path), "--out", str(out), "-q"]) == 0
    assert "welded to 290 vertices" in capsys.readouterr().out
    assert main(["export", str(clip_path), "--out", str(tmp_path / "all.glb"), "--no-weld", "-q"]) == 0
    assert "welded" not in capsys.readouterr().out
    unwelded = (tmp_path / "all.glb").read_bytes()
    (prim,) = primitives(unwelded)
    assert VERTEX_MAP not in prim["attributes"]
    assert load_document(unwelded).accessor(prim["attributes"]["POSITION"]).shape[0] == 1728
    assert out.stat().st_size < 0.3 * (tmp_path / "all.glb").stat().st_size


def capped_tube(segments: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A smooth tube whose seam column is duplicated (as at a UV seam), with flat caps of their own
    vertices (split from the tube's rims, as at a hard edge): vertices (V, 3) and faces (T, 3)."""
    a = np.linspace(0.0, 2 * np.pi, segments + 1)
    ring = np.stack([np.cos(a), np.sin(a)], 1)
    ring[-1] = ring[0]  # the last column repeats the first's positions exactly
    side = np.concatenate([np.c_[ring, np.zeros(segments + 1)], np.c_[ring, np.ones(segments + 1)]])
    i = np.arange(segments)
    top = i + segments + 1
    faces = [np.c_[i, i + 1, top + 1], np.c_[i, top + 1, top]]
    verts = [side]
    for z, flip in ((0.0, True), (1.0, False)):
        base = sum(len(v) for v in verts)
        cap = np.concatenate([np.c_[ring[:-1], np.full(segments, z)], [[0.0, 0.0, z]]])
        tri = np.c_[np.full(segments, base + segments), base + i, base + (i + 1) % segments]
        faces.append(tri[:, ::-1] if flip else tri)
        verts.append(cap)
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int64)


def test_split_smooth_surface_gets_one_normal_and_hard_edges_stay(tmp_path):
    """Without source normals (a plain export), vertices split on a smooth surface share one smooth normal
    and weld; at a hard edge (the caps' rims, one-sided normals 90 degrees apart) they keep their own."""
    rest, faces = capped_tube()
    k = 4
    frames = rest[None] * (1 + 0.1 * np.arange(k)[:, None, None] * rest[None, :, 2:])  # flare the top
    assert not flat_shaded(rest, faces)
    glb = animation(plain_layout(faces, len(rest)), frames.astype(np.float32))
    (prim,) = primitives(glb)
    gd = load_document(glb)
    normal = gd.accessor(prim["attributes"]["NORMAL"])
    clip_vertex = gd.accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64)
    assert len(clip_vertex) == 24 + 2 * 13  # the seam column welded; rims and caps of their own
    where = rest[clip_vertex]
    on_side = np.isin(clip_vertex, np.arange(26))
    radial = np.c_[where[:, :2], np.zeros(len(where))]  # the tube's own normals at rest: radial
    assert np.einsum("ij,ij->i", normal[on_side], radial[on_side]).min() > 0.95
    assert np.abs(normal[~on_side, 2]).min() > 0.99  # caps face along the axis
    assert_clean(validate_many([glb])[0], "tube with a seam and hard rims")


def test_rewritten_attributes_keep_their_type_and_the_vertex_stride():
    """A welded primitive's attributes are written back with their own component type and normalisation,
    each element padded to a 4-byte stride (a VEC3 of bytes), and read back as they were."""
    from pdeanim.gltf.layout import accessor_rows
    from pdeanim.gltf.weld import _vertex_attribute

    doc: dict = {"bufferViews": [], "accessors": []}
    views: list[bytes] = []
    colours = np.arange(15, dtype=np.uint8).reshape(5, 3)
    acc = _vertex_attribute(doc, views, colours, "VEC3", True, True)
    assert doc["bufferViews"][doc["accessors"][acc]["bufferView"]]["byteStride"] == 4
    assert doc["accessors"][acc]["normalized"] and doc["accessors"][acc]["max"] == [12, 13, 14]
    np.testing.assert_array_equal(accessor_rows(doc, views, acc), colours)
    uv = np.linspace(0, 1, 10, dtype=np.float32).reshape(5, 2)
    acc = _vertex_attribute(doc, views, uv, "VEC2", False, False)
    assert "byteStride" not in doc["bufferViews"][doc["accessors"][acc]["bufferView"]]
    np.testing.assert_array_equal(accessor_rows(doc, views, acc), uv)
