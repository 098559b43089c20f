"""Generated glTF models for the browser tests: a textured, skinned, animated creature (a tube along x whose
tail bends), flat-shaded (unwelded triangles, no normals: glTF viewers must shade it flat) or smooth."""

from __future__ import annotations

import io

import numpy as np

from pdeanim.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder


def checker_png(n: int = 16) -> bytes:
    """An n x n checker of two colours, as PNG bytes."""
    from PIL import Image

    img = Image.new("RGB", (n, n))
    for i in range(n):
        for j in range(n):
            img.putpixel((i, j), (220, 140, 40) if (i // 4 + j // 4) % 2 else (60, 110, 200))
    out = io.BytesIO()
    img.save(out, format="PNG")
    return out.getvalue()


def tube(rings: int = 9, sides: int = 6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed-sided tube along x in [0, 2], radius 0.3: positions, UVs, triangles."""
    x = np.linspace(0.0, 2.0, rings)
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    pos = np.stack([np.repeat(x, sides), 0.3 * np.tile(np.cos(a), rings), 0.3 * np.tile(np.sin(a), rings)], 1)
    uv = np.stack([np.repeat(x / 2, sides), np.tile(a / (2 * np.pi), rings)], 1)
    faces = []
    for r in range(rings - 1):
        for s in range(sides):
            p, q = r * sides + s, r * sides + (s + 1) % sides
            faces += [(p, p + sides, q), (q, p + sides, q + sides)]
    return pos.astype(np.float32), uv.astype(np.float32), np.array(faces, np.uint16)


def creature_glb(flat: bool) -> bytes:
    """The creature: two joints (body at the origin, tail at x = 1), the tail turning 40 degrees about z
    over 1 s; a checker texture; flat: every triangle its own three vertices and no NORMAL attribute."""
    pos, uv, faces = tube()
    if flat:
        pos, uv, faces = pos[faces.ravel()], uv[faces.ravel()], np.arange(faces.size, dtype=np.uint16)
    w_tail = np.clip((pos[:, 0] - 0.6) / 0.8, 0.0, 1.0).astype(np.float32)
    weights = np.zeros((len(pos), 4), np.float32)
    weights[:, 0], weights[:, 1] = 1 - w_tail, w_tail
    joints = np.zeros((len(pos), 4), np.uint8)
    joints[:, 1] = 1
    b = GlbBuilder("pdeanim-browser-tests")
    attrs = {"POSITION": b.add_accessor(pos, target=ARRAY_BUFFER, minmax=True),
             "TEXCOORD_0": b.add_accessor(uv, target=ARRAY_BUFFER),
             "JOINTS_0": b.add_accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.add_accessor(weights, target=ARRAY_BUFFER)}
    if not flat:
        import trimesh

        normals = trimesh.Trimesh(pos, faces.reshape(-1, 3), process=False).vertex_normals
        attrs["NORMAL"] = b.add_accessor(normals.astype(np.float32), target=ARRAY_BUFFER)
    idx = b.add_accessor(faces.reshape(-1), target=ELEMENT_ARRAY_BUFFER, acc_type="SCALAR")
    ibm = np.stack([np.eye(4), np.eye(4)]).astype(np.float32)
    ibm[1, 0, 3] = -1.0  # inverse bind of the tail joint (at x = 1)
    ibm_acc = b.add_accessor(ibm.transpose(0, 2, 1).reshape(2, 16), acc_type="MAT4")
    keys = b.add_accessor(np.array([0.0, 0.5, 1.0], np.float32), minmax=True, acc_type="SCALAR")
    angle = np.radians([0.0, 20.0, 40.0]) / 2
    quats = np.stack([np.zeros(3), np.zeros(3), np.sin(angle), np.cos(angle)], 1).astype(np.float32)
    rot = b.add_accessor(quats)
    image = b.add_view(checker_png())
    b.doc.update({
        "scene": 0, "scenes": [{"nodes": [0, 2]}],
        "nodes": [{"name": "body", "children": [1]}, {"name": "tail", "translation": [1.0, 0.0, 0.0]},
                  {"name": "creature", "mesh": 0, "skin": 0}],
        "meshes": [{"name": "creature",
                    "primitives": [{"attributes": attrs, "indices": idx, "material": 0}]}],
        "skins": [{"joints": [0, 1], "inverseBindMatrices": ibm_acc, "skeleton": 0}],
        "animations": [{"name": "wag",
                        "samplers": [{"input": keys, "output": rot, "interpolation": "LINEAR"}],
                        "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]}],
        "materials": [{"name": "hide",
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0,
                                                "roughnessFactor": 0.8}}],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [{"magFilter": 9728, "minFilter": 9728}],
        "images": [{"name": "checker", "bufferView": image, "mimeType": "image/png"}],
    })
    return b.to_glb()
