"""Simulate a surface mesh: tetrahedralize, run XPBD under the scene, and sample the embedded surface as
Poses."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..mesh.io import SurfaceMesh
from ..poses import Poses, make_poses
from ..progress import Progress, sub_progress
from ..records import library_versions
from . import kernels
from .drivers import build_kinematics
from .embedding import Embedding, embed_vertices
from .scene import MAX_TET_SWEEPS, SceneParams
from .tetmesh import TetMesh
from .tetra import TetParams, tetrahedralize
from .xpbd import Ground, Material, SimModel, build_model, project_ground, rest_state, step

COURANT = 0.22
"""Automatic substep: dt <= COURANT * l / c_p (l: 5th-percentile tet size, c_p: pressure-wave speed).

Measured on the cantilever test: at this ratio the settled XPBD deflection is within 5% of a static linear FEM
solve on the same tets, at every resolution; larger steps make XPBD softer as the mesh is refined."""

__all__ = ["MAX_TET_SWEEPS", "SceneParams", "simulate_mesh", "simulate_tets", "auto_substeps"]


AUTO_STRAIN = 0.02
"""With ``young`` unset, Young's modulus is chosen so that gravity compresses the body by about this strain
(E = density x |g| x height / strain): a visible sag and wobble whatever the mesh's units, where a fixed
modulus leaves a 0.15-unit mesh nearly rigid (and capped at max_substeps) and a 15-unit one jelly. Measured
on spot scaled to a 0.15 diagonal (benchmarks/sim_scale_defaults.py): 5% let its thin legs buckle (the top
fell to 63% of its height); 2% sags it 6% and settles, with 241 substeps per frame."""


def auto_young(scene: SceneParams, points: np.ndarray) -> float:
    """Young's modulus (Pa) for ``scene`` on a body with rest points (N, 3): see AUTO_STRAIN."""
    gravity = np.asarray(scene.gravity, np.float64)
    g = float(np.linalg.norm(gravity))
    extent = np.ptp(points, axis=0)
    height = float(np.ptp(points @ (gravity / g))) if g > 0 else float(np.linalg.norm(extent))
    height = height if height > 0 else float(np.linalg.norm(extent)) or 1.0
    return float(scene.density * (g if g > 0 else 9.81) * height / AUTO_STRAIN)


def scene_material(scene: SceneParams, points: np.ndarray) -> Material:
    """The scene's material, with Young's modulus from :func:`auto_young` when the scene leaves it unset."""
    young = scene.young if scene.young is not None else auto_young(scene, points)
    return Material(young, scene.poisson, scene.density, scene.damping)


def characteristic_length(tets: TetMesh) -> float:
    """5th percentile over tets of the edge of a regular tet of the same volume (robust to a few slivers)."""
    return float(np.percentile((6.0 * math.sqrt(2.0) * tets.volumes()) ** (1.0 / 3.0), 5))


def needed_substeps(tets: TetMesh, material: Material, frame_dt: float) -> int:
    """Substeps per frame that resolve the material's fastest waves on this mesh (the COURANT rule)."""
    mu, lam = material.lame()
    wave_speed = math.sqrt((lam + 2.0 * mu) / material.density)
    dt_max = COURANT * characteristic_length(tets) / wave_speed
    return max(1, math.ceil(frame_dt / dt_max))


def auto_substeps(tets: TetMesh, material: Material, frame_dt: float, cap: int) -> tuple[int, bool]:
    """(substeps per frame, capped?) that resolve the material's fastest waves on this mesh."""
    need = needed_substeps(tets, material, frame_dt)
    return min(need, cap), need > cap


def build_scene_model(tets: TetMesh, vertices: np.ndarray, scene: SceneParams) -> tuple[SimModel, Embedding]:
    """The XPBD model (material, gravity, pins, drivers, ground) and the surface embedding."""
    embedding = embed_vertices(tets, vertices)
    times = scene.frame_times()
    kin = build_kinematics(scene.pins, scene.drivers, tets.points, embedding, len(vertices), float(times[-1]))
    material = scene_material(scene, tets.points)
    ground = scene_ground(scene, tets.points)
    model = build_model(tets, material, scene.gravity, kin.fixed, kin if len(kin.fixed) else None, ground,
                        scene.iterations)
    return model, embedding


def scene_ground(scene: SceneParams, points: np.ndarray) -> Ground | None:
    """The scene's ground; with no pins, drivers or ground, one under the lowest point (friction 0.5) so the
    body lands and settles instead of falling forever."""
    if scene.ground is not None:
        g = scene.ground
        return Ground(tuple(g.get("point", (0.0, 0.0, 0.0))), tuple(g.get("normal", (0.0, 1.0, 0.0))),
                      float(g.get("friction", 0.0)))
    gravity = np.asarray(scene.gravity, np.float64)
    if scene.pins or scene.drivers or not np.any(gravity):
        return None
    down = gravity / np.linalg.norm(gravity)
    lowest = points[np.argmax(points @ down)]
    return Ground(tuple(lowest.tolist()), tuple((-down).tolist()), 0.5)


def simulate_tets(tets: TetMesh, vertices: np.ndarray, faces: np.ndarray, scene: SceneParams,
                  progress: Progress | None = None) -> Poses:
    """Poses (F, V, 3) float32 of surface vertices (V, 3) embedded in ``tets`` under ``scene``."""
    started = time.perf_counter()
    report = progress or (lambda fraction, stage: None)
    model, embedding = build_scene_model(tets, np.asarray(vertices, np.float64), scene)
    times = scene.frame_times()
    frame_dt = float(times[1] - times[0]) if len(times) > 1 else 1.0 / scene.fps
    material = scene_material(scene, tets.points)
    substeps, capped = (scene.substeps, False) if scene.substeps else \
        auto_substeps(tets, material, frame_dt, scene.max_substeps)
    needed = needed_substeps(tets, material, frame_dt)
    dt = frame_dt / substeps
    scene.check_work(substeps)  # the same bound the API checked at submission, with the actual substeps
    kernels.set_threads(scene.threads)
    state, spare = rest_state(model), rest_state(model)
    frames = np.empty((len(times), len(vertices), 3), np.float32)
    frames[0] = surface_positions(model, embedding, state.x)
    for f in range(1, len(times)):
        for _ in range(substeps):
            step(model, state, spare, dt)
            state, spare = spare, state
        if not np.all(np.isfinite(state.x)):
            raise ParameterError(
                f"simulation became non-finite at frame {f}: reduce the step or the stiffness"
            )
        frames[f] = surface_positions(model, embedding, state.x)
        report(f / (len(times) - 1), f"simulate {f}/{len(times) - 1}")
    warnings = (
        []
        if not capped
        else [
            f"the substep cap binds: the material needs {needed} substeps per frame, max_substeps is "
            f"{scene.max_substeps}, so the motion is stiffer and more damped than the material; raise "
            "max_substeps or lower young"
        ]
    )
    meta = {
        "source": "simulate",
        "scene": scene.to_dict(),
        "tets": tets.n_tets,
        "tet_points": tets.n_points,
        "young": material.young,
        "young_auto": scene.young is None,
        "substeps": substeps,
        "substeps_capped": capped,
        "substeps_needed": needed,
        "warnings": warnings,
        "dt": dt,
        "colors": model.elements.n_colors,
        "backend": model.backend,
        "ground": None
        if model.ground is None
        else {
            "point": list(model.ground.point),
            "normal": list(model.ground.normal),
            "friction": model.ground.friction,
        },
        "seconds": round(time.perf_counter() - started, 3),
        "versions": library_versions(),
    }
    return make_poses(frames, faces, times, meta)


def surface_positions(model: SimModel, embedding: Embedding, x: np.ndarray) -> np.ndarray:
    """(V, 3) embedded surface positions for tet points x (N, 3), kept on the allowed side of the ground."""
    surface = embedding.apply(x)
    if model.ground is not None:
        project_ground(model.ground, surface, surface)
    return surface


def simulate_mesh(mesh: SurfaceMesh, scene: SceneParams, progress: Progress | None = None,
                  workdir: Path | None = None, cache_dir: Path | None = None) -> Poses:
    """Tetrahedralize ``mesh`` (cached) and simulate it; frames of mesh.vertices order (F, V, 3) float32."""
    if progress is not None:
        progress(0.0, "tetrahedralize")
    started = time.perf_counter()
    tets = tetrahedralize(
        mesh, TetParams(target_tets=scene.target_tets), cache_dir=cache_dir, workdir=workdir
    )
    tet_seconds = time.perf_counter() - started
    poses = simulate_tets(tets, mesh.vertices, mesh.faces, scene, sub_progress(progress, 0.2, 1.0))
    poses.meta.update(tetrahedralize_seconds=round(tet_seconds, 3), mesh_hash=mesh.content_hash,
                      source_file=mesh.source)
    return poses
