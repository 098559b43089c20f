"""KHR_draco_mesh_compression input: GLBs Draco-compressed in the test (DracoPy's encoder, vertex order
kept) read like their plain originals for every glTF input (the scene at rest as uploads and ``fit`` of a
mesh read it, animated poses as ``fit`` reads them, the skinned mesh ``cyclic`` animates), keep their look
in the GLBs written from them, and are held to the declared-size limits before decoding."""

from __future__ import annotations

import numpy as np
import pytest

from pdeanim.cyclic.gaitclip import gait_glb, solve_gait
from pdeanim.cyclic.gaits import GaitParams
from pdeanim.errors import LimitError, MeshInputError
from pdeanim.gltf.document import GltfLimits, load_document
from pdeanim.gltf.draco import DRACO
from pdeanim.gltf.glb import pack_glb, unpack_glb
from pdeanim.gltf.layout import gltf_layout
from pdeanim.gltf.read import read_animated_poses, read_static_mesh
from pdeanim.gltf.skin import load_skinned
from pdeanim.gltf.validate import assert_glb_clean
from pdeanim.mesh.io import load_mesh
from tests.cyclic.rig import CONTROLLED, rig_glb

from .builders import skinned_bar_glb, textured_scene_glb
from .draco_builder import draco_glb

QUANT = 2.0**-16 * 4  # 16-bit positions: a quarter of a step per unit of extent, 4x slack


def _extent(v: np.ndarray) -> float:
    return float(np.ptp(v, axis=0).max())


def test_a_draco_scene_reads_like_the_plain_one():
    src = textured_scene_glb()
    packed = draco_glb(src)
    assert DRACO in unpack_glb(packed)[0]["extensionsRequired"]
    plain_v, plain_f = read_static_mesh(src)
    v, f = read_static_mesh(packed)
    np.testing.assert_array_equal(f, plain_f)
    assert np.abs(v - plain_v).max() <= QUANT * _extent(plain_v) * 4  # node scale 2 on a quantised grid
    mesh = load_mesh(packed, filename="scene.glb")  # what an upload and `pdeanim fit` read
    np.testing.assert_array_equal(mesh.vertices, v)
    layout = gltf_layout(packed)  # the look kept in GLBs written from it: plain views, no Draco left
    assert DRACO not in layout.doc.get("extensionsUsed", [])
    assert all(DRACO not in p.get("extensions", {}) for m in layout.doc["meshes"] for p in m["primitives"])
    uv = [a for a in layout.doc["meshes"][0]["primitives"][0]["attributes"].items() if a[0] == "TEXCOORD_0"]
    assert uv and "bufferView" in layout.doc["accessors"][uv[0][1]]


def test_draco_animated_poses_read_like_the_plain_ones():
    src = skinned_bar_glb()
    plain = read_animated_poses(src, fps=10)
    poses = read_animated_poses(draco_glb(src), fps=10)
    assert poses.vertices.shape == plain.vertices.shape
    assert np.abs(poses.vertices - plain.vertices).max() <= QUANT * _extent(plain.vertices[0]) * 2


def test_a_draco_rig_walks_without_naming_a_joint():
    src = rig_glb(CONTROLLED)
    packed = draco_glb(src)
    skinned, plain = load_skinned(packed), load_skinned(src)
    np.testing.assert_array_equal(skinned.vertex_joints, plain.vertex_joints)
    np.testing.assert_array_equal(skinned.vertex_weights, plain.vertex_weights)
    result = solve_gait(packed, GaitParams.preset("trot"), frames=8)
    assert [leg["foot"] for leg in result.report["plan"]["legs"]] == ["IK-hand.L", "IK-hand.R", "IK-foot.L",
                                                                      "IK-foot.R"]
    assert result.report["contact"]["slide_max_rel"] < 1e-5
    assert_glb_clean(gait_glb(packed, result), "trot of a Draco-compressed rig")


def test_draco_streams_are_held_to_the_declared_limits():
    packed = draco_glb(rig_glb(CONTROLLED))
    with pytest.raises(LimitError, match="KHR_draco_mesh_compression streams"):
        read_static_mesh(packed, GltfLimits(max_decoded_bytes=20_000))
    doc, binary = unpack_glb(packed)
    prim = doc["meshes"][0]["primitives"][0]
    doc["accessors"][prim["attributes"]["POSITION"]]["count"] += 1  # declares one vertex more than it holds
    with pytest.raises(MeshInputError, match="the accessor declares"):
        read_static_mesh(pack_glb(doc, binary))
    doc, binary = unpack_glb(packed)
    view = doc["bufferViews"][prim["extensions"][DRACO]["bufferView"]]
    start = view["byteOffset"]
    broken = binary[:start] + b"\xff" * view["byteLength"] + binary[start + view["byteLength"]:]
    with pytest.raises(MeshInputError, match="cannot decode the Draco stream"):
        read_static_mesh(pack_glb(doc, broken))
    assert load_document(packed).draco  # the stream's accessors are known from the JSON alone
