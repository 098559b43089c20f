"""Hand-built glTF assets for the reader tests: a two-bone skinned bar and node-animated meshes."""

from __future__ import annotations

import numpy as np

from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder

BAR_X = np.array([0.0, 0.5, 1.0, 1.5, 2.0])


def bar_geometry() -> tuple[np.ndarray, np.ndarray]:
    """A flat bar along x: two rows of 5 vertices (y = 0 and y = 0.2), 8 triangles."""
    v = np.concatenate([np.stack([BAR_X, np.zeros(5), np.zeros(5)], 1),
                        np.stack([BAR_X, np.full(5, 0.2), np.zeros(5)], 1)]).astype(np.float32)
    quads = [(i, i + 1, i + 6, i + 5) for i in range(4)]
    f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.uint16)
    return v, f


def bar_weights() -> tuple[np.ndarray, np.ndarray]:
    """Joints/weights per vertex: x < 1 on joint 0, x > 1 on joint 1, x = 1 shared; several sums != 1."""
    raw = {0.0: (1.0, 0.0), 0.5: (0.5, 0.0), 1.0: (0.3, 0.3), 1.5: (0.0, 1.0), 2.0: (0.0, 0.8)}
    w = np.array([raw[x] for x in BAR_X] * 2, np.float32)
    wj = np.zeros((10, 4), np.float32)
    wj[:, :2] = w
    joints = np.zeros((10, 4), np.uint8)
    joints[:, 1] = np.where(wj[:, 1] > 0, 1, 0)  # unused slots point at joint 0, as the spec asks
    return joints, wj


def skinned_bar_glb(interpolation: str = "LINEAR", middle: bool = False) -> bytes:
    """Two joints (root at the origin, child at x = 1); the child turns 90 degrees about z over 1 s.
    ``middle`` puts a non-joint node (z + 0.5) between the two joints."""
    b = GlbBuilder("pdeanim-tests")
    v, f = bar_geometry()
    joints, weights = bar_weights()
    attrs = {"POSITION": b.add_accessor(v, target=ARRAY_BUFFER, minmax=True),
             "JOINTS_0": b.add_accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.add_accessor(weights, target=ARRAY_BUFFER)}
    idx = b.add_accessor(f.reshape(-1), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
    ibm = np.stack([np.eye(4), np.eye(4)]).astype(np.float32)
    ibm[1, 0, 3] = -1.0  # inverse of the child's bind transform (translation by +1 in x)
    if middle:
        ibm[1, 2, 3] = -0.5
    ibm_acc = b.add_accessor(ibm.transpose(0, 2, 1).reshape(2, 16), acc_type="MAT4")
    keys = b.add_accessor(np.array([0.0, 1.0], np.float32), minmax=True, acc_type="SCALAR")
    s = np.sqrt(0.5)
    quats = np.array([[0, 0, 0, 1], [0, 0, s, s]], np.float32)
    if interpolation == "CUBICSPLINE":
        zero = np.zeros(4, np.float32)
        quats = np.array([zero, quats[0], zero, zero, quats[1], zero], np.float32)
    rot = b.add_accessor(quats)
    nodes = [{"name": "root", "children": [1]}, {"name": "tip", "translation": [1.0, 0.0, 0.0]},
             {"name": "bar", "mesh": 0, "skin": 0, "translation": [50.0, 0, 0]}]
    if middle:
        nodes[0]["children"] = [3]
        nodes.append({"name": "offset", "translation": [0.0, 0.0, 0.5], "children": [1]})
    b.doc.update({
        "scene": 0, "scenes": [{"nodes": [0, 2]}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": attrs, "indices": idx}]}],
        "skins": [{"joints": [0, 1], "inverseBindMatrices": ibm_acc}],
        "animations": [{"name": "bend", "samplers": [{"input": keys, "output": rot,
                                                      "interpolation": interpolation}],
                        "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]}],
    })
    return b.to_glb()


def expected_bar(angle: float) -> np.ndarray:
    """Analytic skinned bar for a child rotation ``angle`` about z (weights renormalised)."""
    v, _ = bar_geometry()
    _, w = bar_weights()
    w = w[:, :2] / w[:, :2].sum(axis=1, keepdims=True)
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    moved = (v - [1, 0, 0]) @ rot.T + [1, 0, 0]
    return w[:, :1] * v + w[:, 1:2] * moved


def two_node_glb() -> bytes:
    """Two triangle meshes; the second's parent node translates linearly from 0 to (0, 0, 2) over 2 s."""
    b = GlbBuilder("pdeanim-tests")
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    pos0 = b.add_accessor(tri, target=ARRAY_BUFFER, minmax=True)
    pos1 = b.add_accessor(tri * 2, target=ARRAY_BUFFER, minmax=True)
    keys = b.add_accessor(np.array([0.0, 2.0], np.float32), minmax=True, acc_type="SCALAR")
    moves = b.add_accessor(np.array([[0, 0, 0], [0, 0, 2]], np.float32))
    b.doc.update({
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0, "scale": [1, 1, 3]}, {"children": [2]}, {"mesh": 1, "translation": [5, 0, 0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos0}}]},
                   {"primitives": [{"attributes": {"POSITION": pos1}}]}],
        "animations": [{"samplers": [{"input": keys, "output": moves}],
                        "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}]}],
    })
    return b.to_glb()


def sparse_morph_glb() -> bytes:
    """A quad whose single morph target is a sparse accessor (vertex 2 moves by +1 in z), STEP weights 0 -> 1
    at t = 1 s, on a node scaled by 2."""
    b = GlbBuilder("pdeanim-tests")
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    pos = b.add_accessor(quad, target=ARRAY_BUFFER, minmax=True)
    idx = b.add_accessor(
        np.array([0, 1, 2, 0, 2, 3], np.uint16), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR"
    )
    sparse_idx = b.add_view(np.array([2], np.uint32).tobytes())
    sparse_val = b.add_view(np.array([0, 0, 1], np.float32).tobytes())
    b.doc["accessors"].append({"componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0],
                               "max": [0, 0, 1], "sparse": {"count": 1,
                                                            "indices": {"bufferView": sparse_idx,
                                                                        "componentType": 5125},
                                                            "values": {"bufferView": sparse_val}}})
    target = len(b.doc["accessors"]) - 1
    keys = b.add_accessor(np.array([0.0, 1.0], np.float32), minmax=True, acc_type="SCALAR")
    weights = b.add_accessor(np.array([0.0, 1.0], np.float32), acc_type="SCALAR")
    b.doc.update({
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "scale": [2, 2, 2]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx,
                                    "targets": [{"POSITION": target}]}], "weights": [0.0]}],
        "animations": [{"samplers": [{"input": keys, "output": weights, "interpolation": "STEP"}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}],
    })
    return b.to_glb()


def _png(rgb: tuple[int, int, int]) -> bytes:
    """A 4x4 PNG of one colour with a checker of black pixels."""
    import io

    from PIL import Image

    img = Image.new("RGB", (4, 4), rgb)
    for i in range(0, 4, 2):
        img.putpixel((i, i), (0, 0, 0))
    out = io.BytesIO()
    img.save(out, format="PNG")
    return out.getvalue()


def grid(n: int, z: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An n x n vertex grid in the unit square at height z: positions, normals (+z), UVs and triangles."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    pos = np.stack([u.ravel(), v.ravel(), np.full(n * n, z)], 1).astype(np.float32)
    nrm = np.tile(np.array([0, 0, 1], np.float32), (n * n, 1))
    uv = np.stack([u.ravel(), 1 - v.ravel()], 1).astype(np.float32)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return pos, nrm, uv, faces.astype(np.uint16)


def textured_scene_glb() -> bytes:
    """A small asset with a look: node "body" (rotated, scaled, translated) holding a mesh of two primitives
    (textured material, coloured material; UVs, normals, tangents), its child "hat", and "wing" instancing
    the hat's mesh; one embedded PNG texture with a sampler."""
    b = GlbBuilder("pdeanim-tests")
    prims = []
    for n, z, material in ((4, 0.0, 0), (3, 0.5, 1)):
        pos, nrm, uv, faces = grid(n, z)
        attrs = {"POSITION": b.add_accessor(pos, target=ARRAY_BUFFER, minmax=True),
                 "NORMAL": b.add_accessor(nrm, target=ARRAY_BUFFER),
                 "TEXCOORD_0": b.add_accessor(uv, target=ARRAY_BUFFER)}
        if material == 0:
            tangents = np.tile(np.array([1, 0, 0, 1], np.float32), (len(pos), 1))
            attrs["TANGENT"] = b.add_accessor(tangents, target=ARRAY_BUFFER)
        idx = b.add_accessor(faces.reshape(-1), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
        prims.append({"attributes": attrs, "indices": idx, "material": material})
    pos, nrm, uv, faces = grid(3, 0.0)
    hat = {"attributes": {"POSITION": b.add_accessor(pos * 0.5, target=ARRAY_BUFFER, minmax=True),
                          "TEXCOORD_0": b.add_accessor(uv, target=ARRAY_BUFFER)},
           "indices": b.add_accessor(faces.reshape(-1), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR"),
           "material": 1}
    image_view = b.add_view(_png((200, 40, 40)))
    s = float(np.sqrt(0.5))
    b.doc.update({
        "scene": 0, "scenes": [{"nodes": [0, 2]}],
        "nodes": [{"name": "body", "mesh": 0, "translation": [1.0, 2.0, 3.0], "rotation": [0.0, s, 0.0, s],
                   "scale": [2.0, 2.0, 2.0], "children": [1]},
                  {"name": "hat", "mesh": 1, "translation": [0.0, 1.0, 0.0]},
                  {"name": "wing", "mesh": 1, "translation": [5.0, 0.0, 0.0]}],
        "meshes": [{"name": "body_mesh", "primitives": prims}, {"name": "hat_mesh", "primitives": [hat]}],
        "materials": [{"name": "skin", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                                 "metallicFactor": 0.0}},
                      {"name": "cloth", "pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.3, 0.9, 1.0]},
                       "doubleSided": True}],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}],
        "images": [{"name": "checker", "bufferView": image_view, "mimeType": "image/png"}],
    })
    return b.to_glb()


def clip_vertices(glb: bytes) -> np.ndarray:
    """The clip vertex each vertex of a written GLB shows, in the reader's order (scene nodes depth-first,
    primitives in order): its ``_PDEANIM_VERTEX`` maps when it was welded, else 0, 1, 2, ..."""
    from pdeanim.gltf.document import load_document
    from pdeanim.gltf.scene import scene_order
    from pdeanim.gltf.weld import VERTEX_MAP

    gd = load_document(glb)
    maps, total = [], 0
    for n in scene_order(gd):
        node = gd.doc["nodes"][n]
        for prim in gd.doc["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []:
            total += int(gd.doc["accessors"][prim["attributes"]["POSITION"]]["count"])
            if VERTEX_MAP in prim["attributes"]:
                maps.append(gd.accessor(prim["attributes"][VERTEX_MAP])[:, 0].astype(np.int64))
    return np.concatenate(maps) if maps else np.arange(total)
