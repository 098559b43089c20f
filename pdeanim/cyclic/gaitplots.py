"""Pictures of a gait cycle (matplotlib, Agg canvas): a strip of frames seen from the character's left side,
with the ground passing under it at the travel speed (a planted foot stays on its ground mark) and a dot
under every foot in stance, over a footfall diagram (each leg's stance as a bar over one cycle). Faces take
the model's colours: its base colour texture sampled at each face's UV centroid, or the material colour."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

DEFAULT_COLOUR = np.array([0.62, 0.7, 0.8])
FIGURE_WIDTH = 11.0  # inches
_LIGHT = np.array([0.45, 0.75, 0.5])  # in (forward, up, left) coordinates


def _texture_colours(gd: Any, prim: dict, faces: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """Per-face colours (T, 3) of one primitive: its texture at the UV centroids times the base colour."""
    from matplotlib import image

    mat = gd.item("materials", prim["material"]) if "material" in prim else {}
    pbr = mat.get("pbrMetallicRoughness", {})
    colour = np.asarray(pbr.get("baseColorFactor", [*colour, 1.0])[:3], np.float64)
    tex = pbr.get("baseColorTexture")
    out = np.broadcast_to(colour, (len(faces), 3)).copy()
    uv_key = f"TEXCOORD_{tex.get('texCoord', 0)}" if tex else None
    if tex is None or uv_key not in prim.get("attributes", {}):
        return out
    source = gd.item("textures", tex["index"]).get("source")
    img_spec = gd.item("images", source)
    if "bufferView" not in img_spec:
        return out
    kind = "jpg" if img_spec.get("mimeType") == "image/jpeg" else "png"
    try:
        img = image.imread(io.BytesIO(gd.view_bytes(img_spec["bufferView"])), format=kind)
    except (OSError, SyntaxError, ValueError):  # an image the picture cannot decode: material colour only
        return out
    if img.dtype == np.uint8:
        img = img / 255.0
    uv = gd.accessor(prim["attributes"][uv_key])[faces].mean(axis=1)
    h, w = img.shape[:2]
    px = np.clip((np.mod(uv[:, 0], 1.0) * w).astype(int), 0, w - 1)
    py = np.clip((np.mod(uv[:, 1], 1.0) * h).astype(int), 0, h - 1)
    return out * np.asarray(img[py, px, :3], np.float64)


def face_colours(source: Any, n_faces: int) -> np.ndarray:
    """Colours (T, 3) in [0, 1] of the faces of the first skinned mesh of a glTF (path or bytes), in the
    order :func:`pdeanim.gltf.skin.load_skinned` gives its faces; a neutral colour where none is set."""
    from ..errors import InputError, MeshInputError
    from ..gltf.document import load_document
    from ..gltf.primitives import read_primitive
    from ..gltf.scene import scene_order

    try:
        gd = load_document(source, MeshInputError)
        node = next(gd.list("nodes")[n] for n in scene_order(gd)
                    if "mesh" in gd.list("nodes")[n] and "skin" in gd.list("nodes")[n])
        parts = [_texture_colours(gd, p, read_primitive(gd, p).faces, DEFAULT_COLOUR)
                 for p in gd.item("meshes", node["mesh"]).get("primitives", [])]
        colours = np.concatenate(parts) if parts else np.zeros((0, 3))
    except (InputError, StopIteration, OSError, ValueError, KeyError):
        colours = np.zeros((0, 3))
    return colours if len(colours) == n_faces else np.broadcast_to(DEFAULT_COLOUR, (n_faces, 3)).copy()


def _draw_frame(ax: Any, local: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> None:
    """Fill the triangles of one frame (local (V, 3) forward, up, left coordinates), far side first."""
    tri = local[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    shade = 0.35 + 0.65 * np.abs(n @ (_LIGHT / np.linalg.norm(_LIGHT)))
    order = np.argsort(tri[:, :, 2].mean(axis=1))
    rgb = np.clip(colours[order] * shade[order, None], 0.0, 1.0)
    ax.add_collection(PolyCollection(tri[order][:, :, :2], facecolors=rgb, edgecolors=rgb, linewidths=0.2))


def _local(points: np.ndarray, axes: Any) -> np.ndarray:
    return np.stack([points @ axes.forward, points @ axes.up, points @ axes.left], axis=-1)


def _sole_dots(local: np.ndarray, soles: list[Any], leg_length: float, up: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Where each sole really is, per frame and leg: (K + 1, n, 2) forward and height of its lowest down
    vertices' mean, and (K + 1, n) whether any of its vertices is down (within DOWN of the leg of its rest
    height)."""
    from .contact import DOWN

    at = np.zeros((len(local), len(soles), 2))
    down = np.zeros((len(local), len(soles)), bool)
    for i, sole in enumerate(soles):
        pts = local[:, sole.vertices]  # (K + 1, m, 3) forward, up, left
        on = pts[..., 1] - (sole.rest @ up)[None] <= DOWN * leg_length
        down[:, i] = on.any(axis=1)
        weight = np.where(on, 1.0, 0.0)
        count = np.maximum(weight.sum(axis=1), 1.0)
        at[:, i, 0] = (pts[..., 0] * weight).sum(axis=1) / count
        at[:, i, 1] = np.where(on, pts[..., 1], np.inf).min(axis=1)
    return at, down


def gait_strip_png(path: str | Path, frames: np.ndarray, faces: np.ndarray, colours: np.ndarray, cycle: Any,
                   panels: int = 6, title: str | None = None, soles: list[Any] | None = None) -> Path:
    """Write the strip of ``panels`` frames over one cycle and the footfall diagram of a
    :class:`pdeanim.cyclic.locomotion.GaitCycle` whose skinned frames (K + 1, V, 3) are given. With the
    legs' ``soles`` (vertex indices into frames, :func:`.contact.soles`), a dot marks where each sole really
    is in every frame it is down; else under each foot joint in its planned stance."""
    plan, k = cycle.plan, len(frames) - 1
    picks = np.round(np.arange(panels) * k / panels).astype(int)
    local = _local(np.asarray(frames, np.float64), plan.axes)
    ground = plan.skeleton.ground
    lo, hi = local[..., :2].min(axis=(0, 1)), local[..., :2].max(axis=(0, 1))
    pad = 0.06 * (hi - lo).max()
    aspect = (hi[0] - lo[0] + 2 * pad) / (hi[1] - ground + 2 * pad)
    strip = FIGURE_WIDTH / panels / aspect + 0.3
    diagram = 0.16 * len(plan.legs) + 0.5
    height = strip + diagram + 0.9
    fig = Figure(figsize=(FIGURE_WIDTH, height), dpi=100)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, panels, height_ratios=[strip, diagram], hspace=0.9 / (strip + diagram),
                            left=0.1, right=0.98, top=1 - 0.35 / height, bottom=0.5 / height, wspace=0.05)
    feet = [leg.foot for leg in plan.legs]
    spacing = 0.25 * plan.leg_length
    if soles is not None:
        sole_at, sole_down = _sole_dots(local, soles, plan.leg_length, plan.axes.up)
    for col, f in enumerate(picks):
        ax = fig.add_subplot(grid[0, col])
        _draw_frame(ax, local[f], faces, colours)
        shift = -cycle.speed * cycle.times[f]
        marks = np.arange(np.floor((lo[0] - pad - shift) / spacing),
                          np.ceil((hi[0] + pad - shift) / spacing) + 1)
        ax.plot([lo[0] - pad, hi[0] + pad], [ground, ground], color="#555", lw=0.8)
        for x in marks * spacing + shift:
            ax.plot([x, x], [ground, ground - 0.6 * pad], color="#555", lw=0.6)
        if soles is None:
            foot = _local(cycle.world[f, feet, :3, 3], plan.axes)
            dots, down = np.stack([foot[:, 0], np.full(len(feet), ground)], axis=1), cycle.paths.stance[f]
        else:
            dots, down = sole_at[f], sole_down[f]
        near = np.array([leg.side >= 0 for leg in plan.legs])
        for mask, colour in ((down & near, "#d62728"), (down & ~near, "#1f77b4")):
            ax.scatter(dots[mask, 0], dots[mask, 1], s=14, color=colour, zorder=5)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(ground - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(f"t = {cycle.times[f] / cycle.params.period:.2f}", fontsize=8)
    _footfalls(fig.add_subplot(grid[1, :]), cycle, picks)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.savefig(path)
    return Path(path)


def _footfalls(ax: Any, cycle: Any, picks: np.ndarray) -> None:
    """Stance bars of every leg over one cycle (red: near side, blue: far side), panel times dashed."""
    t = cycle.times / cycle.params.period
    for i, leg in enumerate(cycle.plan.legs):
        down = cycle.paths.stance[:, i]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            end = t[min(b, len(t) - 1)]
            ax.barh(i, end - t[a], left=t[a], height=0.6, color="#d62728" if leg.side >= 0 else "#1f77b4")
    for f in picks:
        ax.axvline(t[f], color="#999", lw=0.6, ls="--")
    ax.set_yticks(range(len(cycle.plan.legs)), [leg.name for leg in cycle.plan.legs], fontsize=7)
    ax.set_ylim(len(cycle.plan.legs) - 0.4, -0.6)
    ax.set_xlim(0.0, 1.0)
    ax.tick_params(axis="x", labelsize=7)
    ax.set_xlabel(f"cycle ({cycle.params.gait}, duty {cycle.duty:.2f}, "
                  f"{cycle.speed:.3g} units/s)", fontsize=8)
