"""A gait cycle as output: the whole glTF scene's vertices over one cycle (the skinned mesh moving, other
meshes at rest), fitted into a looping dynamic-PDE clip whose coefficients header carries the gait and the
travel speed, or written as a looping GLB that keeps the model's materials and textures; with the foot
contact figures measured on what is shipped."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import container
from ..clipparts import ClipParts
from ..errors import MeshInputError
from ..poses import Poses, make_poses
from ..progress import Progress, no_progress, sub_progress
from .bodyplan import plan_of
from .contact import Sole, contact_report, soles
from .gaits import GaitParams
from .locomotion import GaitCycle, cycle_poses, cycle_times, solve_cycle


@dataclass(frozen=True)
class GaitResult:
    """A solved cycle, the scene's poses over it (K + 1 frames, the last repeating the first), the feet's
    soles (scene vertex indices) and a JSON-able report (legs found, gait, travel, contact figures)."""

    cycle: GaitCycle
    poses: Poses
    soles: list[Sole]
    report: dict[str, Any]


def skinned_offset(source: str | Path | bytes) -> int:
    """Index of the first skinned mesh's first vertex in the scene's vertex order (that of
    :func:`pdeanim.gltf.read.read_static_mesh`)."""
    from ..gltf.document import load_document, malformed_as
    from ..gltf.read import mesh_instances

    gd = load_document(source, MeshInputError)
    with malformed_as(MeshInputError):
        offset = 0
        for inst in mesh_instances(gd):
            if inst.skin is not None:
                return offset
            offset += len(inst.primitive.positions)
    raise MeshInputError("the glTF file has no skinned mesh (no node with both a mesh and a skin)")


def solve_gait(source: str | Path | bytes, params: GaitParams, frames: int = 24,
               legs: list[str] | None = None, forward: object = None, root: str | None = None) -> GaitResult:
    """The cycle of the skinned glTF ``source`` (path or bytes) and the scene's poses over it."""
    from ..gltf.read import read_static_mesh
    from ..gltf.skin import load_skinned, skin_vertices

    try:
        skinned = load_skinned(source)
    except MeshInputError as exc:
        raise MeshInputError(f"a gait animates a skinned glTF/GLB: {exc}") from exc
    plan = plan_of(skinned, legs, forward, root)
    cycle = solve_cycle(plan, params, cycle_times(params, frames))
    own = cycle_poses(skinned, cycle)
    scene, faces = read_static_mesh(source)
    start = skinned_offset(source)
    n = own.vertices.shape[1]
    verts = np.broadcast_to(scene.astype(np.float32), (len(own.vertices), *scene.shape)).copy()
    verts[:, start:start + n] = own.vertices
    poses = make_poses(verts, faces, own.times, meta=own.meta)
    rest = skin_vertices(skinned, plan.skeleton.rest)
    feet = [Sole(s.vertices + start, s.rest, s.above) for s in soles(skinned, plan, rest)]
    report = {"plan": plan.describe(), **cycle.metadata(),
              "ik_miss_max": float(cycle.miss.max()), "contact": contact_report(poses.vertices, cycle, feet)}
    return GaitResult(cycle, poses, feet, report)


def fit_gait_clip(result: GaitResult, target_rel_rms: float, progress: Progress | None = None) -> ClipParts:
    """Fit the scene's poses into a looping dynamic-PDE clip; its coefficients header gets "gait" and
    "travel" (speed in units per second along "direction"), its report the same and the contact figures of
    the clip itself."""
    from ..fit import FitOptions, fit_poses
    from ..fit.encode import decode

    progress = progress or no_progress
    options = FitOptions(loop=True, target_rel_rms=target_rel_rms)
    parts = fit_poses(result.poses, options, progress=sub_progress(progress, 0.0, 0.95))
    meta = result.cycle.metadata()
    coefficients = container.with_header(parts.coefficients, meta)
    clip = decode(ClipParts(parts.topology, coefficients))
    cycle = result.cycle
    frames = np.asarray(clip.evaluate(cycle.times / cycle.params.period), np.float32)
    report = {**parts.report, **result.report, "kind": "dynamic-pde", "producer": "cyclic-gait",
              "contact_clip": contact_report(frames, cycle, result.soles)}
    progress(1.0, "cyclic: done")
    return ClipParts(parts.topology, coefficients, report)


def gait_glb(source: str | Path | bytes, result: GaitResult) -> bytes:
    """The cycle as a looping morph-target GLB keeping the source's look (materials, textures, UVs)."""
    from ..gltf.compact import PackOptions, layout_animation_glb
    from ..gltf.layout import gltf_layout
    from ..gltf.write import _check_times, _key_plan

    data = Path(source).read_bytes() if isinstance(source, str | Path) else bytes(source)
    layout = gltf_layout(data)
    frames = np.asarray(result.poses.vertices, np.float32)
    times = _check_times(result.poses.times, len(frames))
    key_times, key_target, n_targets = _key_plan(frames, times, True)
    names = [f"t{x:.4f}" for x in result.poses.times / result.cycle.params.period]
    return layout_animation_glb(layout, frames, key_times, key_target, n_targets, options=PackOptions(),
                                names=names[:n_targets], loop=True)
