"""GLBs that keep a glTF source's look (materials, textures, UVs, primitives, node names; skins baked) and
small animation GLBs (KHR_mesh_quantization + EXT_meshopt_compression): structure, round trips through the
reader (which decodes meshopt), and 0 errors / 0 warnings from the Khronos validator."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from pdeanim.errors import ParameterError
from pdeanim.gltf.compact import LayoutFrames, PackOptions, layout_animation_glb, layout_frame_glb
from pdeanim.gltf.document import load_document
from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.layout import gltf_layout, plain_layout, source_layout
from pdeanim.gltf.meshopt import EXT
from pdeanim.gltf.read import read_animated_poses, read_static_mesh
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.weld import VERTEX_MAP
from pdeanim.gltf.write import animation_glb
from pdeanim.mesh.io import load_mesh
from tests.ci import missing

from .builders import clip_vertices, skinned_bar_glb, textured_scene_glb

LOOK_KEYS = ("materials", "textures", "samplers")


def moving_frames(rest: np.ndarray, k: int) -> np.ndarray:
    """K frames of a wave over the rest positions (frame 0 = rest)."""
    phase = np.arange(k)[:, None, None]
    return rest[None] + 0.05 * phase * np.sin(rest[None, :, :1] * 3 + phase)


def uv_of(glb: bytes, mesh: int, prim: int) -> np.ndarray:
    gd = load_document(glb)
    return gd.accessor(gd.doc["meshes"][mesh]["primitives"][prim]["attributes"]["TEXCOORD_0"])


def test_mesh_loader_and_layout_share_the_file_order():
    src = textured_scene_glb()
    rest, faces = read_static_mesh(src)
    mesh = load_mesh(src, filename="scene.glb")
    np.testing.assert_array_equal(mesh.vertices, rest)  # every primitive's vertices, depth-first, in order
    layout = gltf_layout(src)
    assert layout.n_vertices == len(rest) and len(layout.slots) == 4
    assert [(s.start, s.stop) for s in layout.slots] == [(0, 16), (16, 25), (25, 34), (34, 43)]
    np.testing.assert_array_equal(layout.faces, mesh.faces)


def test_frame_keeps_the_look_and_the_positions():
    src = textured_scene_glb()
    rest, _ = read_static_mesh(src)
    moved = moving_frames(rest, 3)[2]
    glb = layout_frame_glb(gltf_layout(src), moved)
    doc, _ = unpack_glb(glb)
    sdoc, _ = unpack_glb(src)
    for key in LOOK_KEYS:
        assert doc[key] == sdoc[key]
    assert doc["images"][0]["mimeType"] == "image/png" and doc["images"][0]["name"] == "checker"
    assert load_document(glb).view_bytes(doc["images"][0]["bufferView"]) == \
        load_document(src).view_bytes(sdoc["images"][0]["bufferView"])
    assert [n["name"] for n in doc["nodes"]] == ["body", "hat", "wing"]
    assert [len(m["primitives"]) for m in doc["meshes"]] == [2, 1, 1]  # the instanced mesh got its own copy
    assert [p["material"] for m in doc["meshes"] for p in m["primitives"]] == [0, 1, 1, 1]
    assert "TANGENT" not in doc["meshes"][0]["primitives"][0]["attributes"]  # stale after deformation
    np.testing.assert_array_equal(uv_of(glb, 0, 0), uv_of(src, 0, 0))
    np.testing.assert_array_equal(uv_of(glb, 2, 0), uv_of(src, 1, 0))
    back, _ = read_static_mesh(glb)
    np.testing.assert_allclose(back, moved, atol=1e-5)  # float32 local positions through node transforms
    assert_clean(validate_many([glb])[0], "frame with the source's look")


def test_animation_keeps_the_look_quantised_and_compressed():
    src = textured_scene_glb()
    rest, _ = read_static_mesh(src)
    k = 6
    frames = moving_frames(rest, k)
    times = np.arange(k, dtype=np.float32) / 10
    names = [f"f{i}" for i in range(k)]
    glb = layout_animation_glb(gltf_layout(src), frames, times, np.arange(k), k, names=names)
    doc, _ = unpack_glb(glb)
    assert doc["extensionsRequired"] == ["KHR_mesh_quantization", EXT] == doc["extensionsUsed"]
    assert doc["buffers"][1]["extensions"][EXT] == {"fallback": True} and "uri" not in doc["buffers"][1]
    assert "skins" not in doc and [n.get("name") for n in doc["nodes"][:3]] == ["body", "hat", "wing"]
    # the dequantising child node comes first, so depth-first order is kept
    assert doc["nodes"][0]["children"][0] == 3 and doc["nodes"][3]["name"] == "body_mesh"
    assert len(doc["animations"][0]["channels"]) == 3
    assert doc["meshes"][0]["extras"]["targetNames"] == [f"f{i}" for i in range(k)]
    sdoc, _ = unpack_glb(src)
    assert all(doc[key] == sdoc[key] for key in LOOK_KEYS)
    trs = ("matrix", "translation", "rotation", "scale")
    for node, source_node in zip(doc["nodes"][:3], sdoc["nodes"], strict=True):  # source transforms untouched
        assert {k: node.get(k) for k in trs} == {k: source_node.get(k) for k in trs}
    slot = next(s for s in gltf_layout(src).slots if (s.mesh, s.prim) == (1, 0))
    gd = load_document(glb)  # the primitive in fetch order: its UVs follow its _PDEANIM_VERTEX map
    shown = gd.accessor(gd.doc["meshes"][1]["primitives"][0]["attributes"][VERTEX_MAP])[:, 0].astype(int)
    np.testing.assert_array_equal(uv_of(glb, 1, 0), uv_of(src, 1, 0)[shown - slot.start])
    back = read_animated_poses(glb, fps=10)
    # the body node scales by 2: world error <= 2 x half a 14-bit step of its local extent; 2x margin
    step = 2 * float(np.ptp(frames.reshape(-1, 3), axis=0).max()) / (2**14 - 1)
    # every primitive is written in fetch order (welded or not), with its _PDEANIM_VERTEX map
    np.testing.assert_allclose(back.vertices, frames[:, clip_vertices(glb)], atol=step)
    plain = layout_animation_glb(gltf_layout(src), frames, times, np.arange(k), k,
                                 options=PackOptions(quantize=False, compress=False))
    np.testing.assert_allclose(read_animated_poses(plain, fps=10).vertices, frames[:, clip_vertices(plain)],
                               atol=1e-5)
    reports = validate_many([glb, plain])
    for label, report in zip(["compact look animation", "float look animation"], reports, strict=True):
        assert_clean(report, label)


def test_skinned_source_is_baked_and_its_skin_dropped():
    src = skinned_bar_glb()
    rest, _ = read_static_mesh(src)
    layout = gltf_layout(src)
    frames = moving_frames(rest, 4)
    frame = layout_frame_glb(layout, frames[1])
    anim = layout_animation_glb(layout, frames, np.arange(4, dtype=np.float32), np.arange(4), 4)
    for glb in (frame, anim):
        doc, _ = unpack_glb(glb)
        assert "skins" not in doc and all("skin" not in n for n in doc["nodes"])
        attrs = doc["meshes"][0]["primitives"][0]["attributes"]
        assert not any(a.startswith(("JOINTS_", "WEIGHTS_")) for a in attrs)
        assert [n.get("name") for n in doc["nodes"][:3]] == ["root", "tip", "bar"]
    np.testing.assert_allclose(read_static_mesh(frame)[0], frames[1], atol=1e-5)
    np.testing.assert_allclose(read_animated_poses(anim, fps=1).vertices, frames[:, clip_vertices(anim)],
                               atol=1e-3)
    for report in validate_many([frame, anim]):
        assert_clean(report, "baked skin")


def test_plain_and_obj_layouts(spot_path):
    data = spot_path.read_bytes()
    mesh = load_mesh(spot_path)
    layout = source_layout(data, "spot.obj", mesh.faces, len(mesh.vertices))
    assert layout.source == "obj"  # UVs kept
    frames = moving_frames(mesh.vertices, 3)
    glb = layout_animation_glb(layout, frames, np.arange(3, dtype=np.float32), np.arange(3), 3)
    assert uv_of(glb, 0, 0).shape == (len(mesh.vertices), 2)
    mismatch = source_layout(data, "spot.obj", np.array([[0, 1, 2]]), 7)
    assert mismatch.source == "plain" and "vertices" in mismatch.notes[0]
    assert source_layout(b"not a glb", "x.glb", mesh.faces, len(mesh.vertices)).source == "plain"
    assert_clean(validate_many([glb])[0], "obj animation with UVs")
    with pytest.raises(ParameterError):
        layout_frame_glb(plain_layout(mesh.faces, len(mesh.vertices)), frames[0, :5])
    with pytest.raises(ParameterError):
        PackOptions(position_bits=16)
    with pytest.raises(ParameterError):
        plain_layout(mesh.faces, 7)  # faces out of range (would crash the native vertex-cache optimiser)


def test_fast_frame_writer_matches_the_plain_one(spot_path):
    src = textured_scene_glb()
    rest, _ = read_static_mesh(src)
    spot = load_mesh(spot_path)
    obj = source_layout(spot_path.read_bytes(), "spot.obj", spot.faces, len(spot.vertices))
    cases = [(gltf_layout(src), moving_frames(rest, 3)[2]), (obj, spot.vertices * 1.1)]
    for layout, positions in cases:
        fast, slow = LayoutFrames(layout)(positions), layout_frame_glb(layout, positions)
        dfast, bfast = unpack_glb(fast)
        dslow, bslow = unpack_glb(slow)
        assert dfast == dslow  # same JSON, bounds included
        # normals: float32 incidence product vs the float64 path, within 1e-6 (see FaceNormals)
        np.testing.assert_allclose(np.frombuffer(bfast, np.float32), np.frombuffer(bslow, np.float32),
                                   atol=1e-6)
        assert_clean(validate_many([fast])[0], "fast frame")


def test_reader_decodes_gltfpack_meshopt_output(tmp_path, morph):
    """An independent EXT_meshopt_compression encoder (gltfpack -cc: quantised, octahedral-filtered normals,
    reordered vertices) round-trips through pdeanim's reader; vertices are matched by their rest position."""
    from scipy.spatial import cKDTree

    gltfpack = (
        Path(__file__).resolve().parents[2] / "tools" / "gltfpack" / "node_modules" / ".bin" / "gltfpack"
    )
    if not gltfpack.exists():
        missing("tools/gltfpack is not installed: run script/setup")  # a failure under CI
    frames, faces, times = morph
    src, out = tmp_path / "in.glb", tmp_path / "out.glb"
    src.write_bytes(animation_glb(frames[::8], np.arange(len(frames[::8])) / 10, faces))
    subprocess.run([str(gltfpack), "-cc", "-i", str(src), "-o", str(out)], check=True, capture_output=True)
    doc, _ = unpack_glb(out.read_bytes())
    assert EXT in doc["extensionsRequired"]
    step = max(max(n.get("scale", [0.0])) for n in doc["nodes"])  # gltfpack's dequantising node scale
    poses = read_animated_poses(out.read_bytes(), fps=10)
    assert poses.vertices.shape == frames[::8].shape
    _, match = cKDTree(poses.vertices[0]).query(frames[0])
    # base and delta each round to half a step: at most one step, 2x margin
    np.testing.assert_allclose(poses.vertices[:, match], frames[::8], atol=2 * step)
