"""``pdeanim export CLIP --fps 30 --out FILE.glb [--mesh SOURCE]``: the clip as a morph-target animation,
quantised and meshopt-compressed by default, keeping a glTF/OBJ source mesh's look when ``--mesh`` names
it."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..clip import load_clip_file
from ..errors import InputError
from ..gltf.clipexport import clip_animation_glb
from ..gltf.compact import PackOptions
from ..progress import cli_progress


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` sub-command."""
    p = subparsers.add_parser(
        "export", help="write a clip as an animated GLB (morph targets + weights animation)",
        description="Sample a clip at --fps over its duration (last frame included; looping clips loop "
                    "seamlessly) and write a glTF 2.0 binary file. By default positions are quantised to a "
                    "grid no finer than the clip's own error needs (its rounding adds at most a quarter of "
                    "the clip's RMS error; KHR_mesh_quantization), normals to bytes, "
                    "and every stream is compressed with EXT_meshopt_compression (three.js GLTFLoader with "
                    "MeshoptDecoder, Babylon.js and gltfpack read it); --no-compress --no-quantize writes "
                    "plain float32.")
    p.add_argument("clip", metavar="CLIP", help="clip file written by `pdeanim fit` or `pdeanim cyclic`")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second of the animation (default 30)")
    p.add_argument("--out", required=True, metavar="FILE.glb", help="output GLB path")
    p.add_argument("--mesh", metavar="SOURCE",
                   help="the mesh the clip was made from (GLB/glTF: keep its materials, textures, UVs, "
                        "primitives and node names; OBJ: keep its UVs); must have the clip's vertex count")
    p.add_argument("--no-quantize", dest="quantize", action="store_false",
                   help="store float32 positions and normals instead of the integer grid and bytes")
    p.add_argument("--no-compress", dest="compress", action="store_false",
                   help="do not use EXT_meshopt_compression (for viewers without a meshopt decoder)")
    p.add_argument("--position-bits", type=int, default=None, metavar="N",
                   help="bits per axis of the position grid over the animation's extent, 8..15 (14: a step "
                        "of 6.1e-5 of the extent); by default the step follows the clip's own error: the "
                        "grid adds at most a quarter of the clip's RMS error (14 bits for a clip that "
                        "stores no error)")
    p.add_argument("--normal-targets", dest="normals", action="store_true",
                   help="also write per-frame normal deltas (35-40%% larger on smooth meshes; by default "
                        "every frame is lit with the first frame's normals)")
    p.add_argument("--no-normal-targets", dest="normals", action="store_false",
                   help="leave out per-frame normal deltas (the default)")
    p.add_argument("--no-weld", dest="weld", action="store_false",
                   help="keep one vertex per clip vertex, in clip order (by default vertices whose positions "
                        "in every frame, normals and UVs are equal are written once, as gltfpack does: a "
                        "flat-shaded, unwelded mesh shrinks several times)")
    # --quantize was an opt-in flag before quantising became the default: still accepted, hidden
    p.add_argument("--quantize", dest="quantize", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run, normals=False)


def run(args: argparse.Namespace) -> int:
    """Load the clip (and source mesh), sample it and write the GLB; prints what was written."""
    clip = load_clip_file(args.clip)
    layout = None
    if args.mesh:
        from ..gltf.layout import source_layout

        path = Path(args.mesh)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise InputError(f"cannot read --mesh {path}: {exc}") from exc
        layout = source_layout(data, path.name, clip.faces, clip.n_vertices)
        for note in layout.notes:
            print(f"note: {note}")
    options = PackOptions(args.quantize, args.compress, args.position_bits, args.normals, args.weld)
    progress = cli_progress("export", args.quiet)
    try:
        glb = clip_animation_glb(clip, args.fps, options=options, layout=layout, progress=progress)
    finally:
        if progress is not None:
            progress.close()
    out = Path(args.out)
    out.write_bytes(glb)
    packing = [w for w, on in (("quantised", args.quantize), ("meshopt", args.compress)) if on]
    joints = _joints(glb)
    if joints:  # a clip with a bone layer, written as a skinned animation (float32, not packed)
        packing = [f"skinned, {joints} joints, float32"]
    written = _written_vertices(glb)
    if written != clip.n_vertices:
        packing.append(f"welded to {written} vertices")
    look = f", look of {layout.source} source" if layout is not None and layout.source != "plain" else ""
    loop = ", looping" if clip.looping else ""
    packed = ", " + " + ".join(packing) if packing else ""
    print(
        f"wrote {out} ({len(glb)} bytes, {clip.n_vertices} vertices, {len(clip.frame_times)} source frames, "
        f"{args.fps:g} fps{loop}{packed}{look})"
    )
    return 0


def _written_vertices(glb: bytes) -> int:
    """Vertices the GLB's primitives hold in all."""
    from ..gltf.glb import unpack_glb

    doc, _ = unpack_glb(glb)
    return sum(doc["accessors"][p["attributes"]["POSITION"]]["count"]
               for m in doc.get("meshes", []) for p in m["primitives"] if "POSITION" in p["attributes"])


def _joints(glb: bytes) -> int:
    """Joints of the GLB's skins (0: a morph-target animation)."""
    from ..gltf.glb import unpack_glb

    doc, _ = unpack_glb(glb)
    return sum(len(skin["joints"]) for skin in doc.get("skins", []))
