"""The pipeline stages a job runs (inside the child process): simulate, fit, cyclic and export. Library
modules are imported here, lazily, so the worker starts even before a stage exists in this build."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pdeanim.poses import poses_to_bytes
from pdeanim.progress import Progress, sub_progress
from pdeanim.records import jsonable
from pdeanim_service.settings import Settings
from pdeanim_service.store.blobs import BlobStore

from .clipstore import store_clip

log = logging.getLogger("pdeanim.worker")
Partial = Callable[[dict], None]  # hands a part of the result to the parent before the stage goes on
SIMULATE_SHARE = 0.75  # part of the progress bar a simulate + fit job gives to the simulation
EXPORT_DECODE_BYTES = 256 << 20  # an export job decodes a clip whole up to this, else evaluates it by blocks


def _mesh(job: dict, blobs: BlobStore, settings: Settings):  # noqa: ANN202 - SurfaceMesh
    from pdeanim.mesh.io import MeshLimits, load_mesh

    limits = MeshLimits(settings.max_upload_bytes, settings.max_vertices, settings.max_faces)
    return load_mesh(blobs.get(job["mesh"]["blob_key"]), filename=job["mesh"]["filename"], limits=limits)


def _labelled(progress: Progress) -> Progress:
    """Progress whose stage names the fit."""
    def labelled(fraction: float, stage: str) -> None:
        progress(fraction, stage if stage.startswith("fit") else f"fit: {stage}")
    return labelled


def _fit(poses, options: dict, blobs: BlobStore, progress: Progress, memory: int,  # noqa: ANN001
         tol=None, skin_source: Callable[[], bytes] | None = None) -> dict:  # noqa: ANN001
    """Fit and store the clip; a missed target fails the job (TargetNotMetError, not retried) unless the
    options ask for ``best_effort``. With bones, ``skin_source`` gives the skinned glTF the poses were read
    from: its own skeleton is the bone layer, as ``pdeanim fit`` does with a skinned glTF."""
    from pdeanim.errors import TargetNotMetError
    from pdeanim.fit import FitOptions, fit_poses, target_shortfall
    from pdeanim.fit.budget import check_fit_memory

    check_fit_memory(poses.n_frames, poses.n_vertices, memory, tol)  # refused now, not after minutes of work
    fit_options = FitOptions.from_dict(options)
    skin = _source_skin(skin_source, poses) if fit_options.bones != 0 and skin_source is not None else None
    parts = fit_poses(poses, fit_options, progress=_labelled(progress), tolerances=tol, skin=skin)
    shortfall = target_shortfall(parts.report)
    if shortfall and not fit_options.best_effort:
        raise TargetNotMetError(
            f"{shortfall} (ask for best_effort: true in the fit options to keep the clip)"
        )
    return store_clip(parts, blobs, poses.n_frames, poses.n_vertices)


def run_simulate(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
                 partial: Partial | None = None) -> dict:
    """Mesh -> poses (stored as POSES.npz), and the fit of them when ``then_fit``. The tets come from the
    blob store (shared by every worker); with ``then_fit`` the poses are handed to ``partial`` (stored by
    the parent, fenced) before the fit starts, so a failing fit does not lose them."""
    from pdeanim.sim.scene import SceneParams
    from pdeanim.sim.simulate import simulate_mesh

    from .tetcache import check_only_shared, shared_tets

    spec = job["params"]
    share = SIMULATE_SHARE if spec.get("then_fit") else 1.0
    mesh = _mesh(job, blobs, settings)
    scene = SceneParams.from_dict(spec["params"])
    if spec.get("then_fit"):
        from pdeanim.fit.budget import check_fit_memory

        check_fit_memory(scene.frames, len(mesh.vertices), settings.job_memory_limit(),  # before simulating
                         settings.fit_tolerances())
    progress(0.0, "tetrahedralize")
    tet_dir = workdir / "tets"
    tet_key = shared_tets(mesh, scene.target_tets, blobs, tet_dir, workdir)
    poses = simulate_mesh(mesh, scene, progress=sub_progress(progress, 0.0, share), workdir=workdir,
                          cache_dir=tet_dir)
    check_only_shared(tet_dir, tet_key)
    out: dict[str, Any] = {"poses": {"blob_key": blobs.put(poses_to_bytes(poses)), "n_frames": poses.n_frames,
                                     "n_vertices": poses.n_vertices, "meta": jsonable(poses.meta)},
                           "tet_cache_key": tet_key}
    if spec.get("then_fit"):
        if partial is not None:
            partial({**out, "next_stage": "fit"})
        out["clip"] = _fit(poses, spec["fit"], blobs, sub_progress(progress, share, 1.0),
                           settings.job_memory_limit(), settings.fit_tolerances())
    return out


def run_fit(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
            partial: Partial | None = None) -> dict:
    """Stored poses -> clip. The memory estimate is checked from the poses row before the poses are loaded
    (refused at once, with the message of the check after loading)."""
    from pdeanim.poses import PoseLimits, load_poses_npz

    limits = PoseLimits(max_frames=settings.max_frames, max_vertices=settings.max_vertices,
                        max_bytes=settings.max_pose_bytes)
    tol, options = settings.fit_tolerances(), job["params"]["params"]
    stored = job["poses"]
    if isinstance(stored.get("n_frames"), int) and isinstance(stored.get("n_vertices"), int):
        if _fit_in_tasks(stored["n_frames"], stored["n_vertices"], options, settings, tol):
            from pdeanim.fit import FitOptions

            from .windowtasks import plan_fit_streamed

            fit_options = FitOptions.from_dict(options).validate()
            planned = plan_fit_streamed(job["id"], stored["blob_key"], limits, fit_options, tol, blobs,
                                        _labelled(progress), workdir)
            if planned is not None:
                return planned
    poses = load_poses_npz(blobs.get(stored["blob_key"]), limits)
    if _fit_in_tasks(poses.n_frames, poses.n_vertices, options, settings, tol):
        from pdeanim.fit import FitOptions

        from .windowtasks import plan_fit

        fit_options = FitOptions.from_dict(options).validate()
        return plan_fit(job["id"], poses, fit_options, tol, blobs, _labelled(progress), workdir)
    source = _gltf_source(job, blobs)
    if source is not None:
        poses.meta["animation"] = stored["animation"]
    return {"clip": _fit(poses, options, blobs, progress, settings.job_memory_limit(), tol, source)}


def _gltf_source(job: dict, blobs: BlobStore) -> Callable[[], bytes] | None:
    """The stored glTF of the job's mesh (read when called) when the poses were read from a glTF animation
    (their row records it) and the mesh is a glTF, else None."""
    mesh, stored = job.get("mesh") or {}, job.get("poses") or {}
    if not isinstance(stored.get("animation"), dict) or not mesh.get("blob_key"):
        return None
    if not str(mesh.get("filename", "")).lower().endswith((".glb", ".gltf")):
        return None
    return lambda: blobs.get(mesh["blob_key"])


def _source_skin(source: Callable[[], bytes], poses):  # noqa: ANN001, ANN202
    """The skinned glTF's own bones for the poses (pdeanim.bones.gltfskin), or None where the file has no
    skin or does not match the poses (logged; the fit then decomposes the motion into bones itself)."""
    from pdeanim.bones.gltfskin import skin_bones
    from pdeanim.errors import PosesInputError

    try:
        return skin_bones(source(), poses)
    except PosesInputError as exc:
        log.warning("the mesh's glTF skin does not fit the poses (%s): bones by decomposition", exc)
        return None


def _fit_in_tasks(n_frames: int, n_vertices: int, options: dict, settings: Settings, tol) -> bool:  # noqa: ANN001
    """Whether the fit of (F, V) poses runs as window tasks; LimitError (the job fails at once) when its
    memory estimate (of the largest task, or of the fit in this process) is over the job memory limit."""
    from pdeanim.fit import FitOptions
    from pdeanim.fit.budget import check_fit_memory
    from pdeanim.fit.windowed import windowed_applies

    tasks = settings.fit_window_tasks and windowed_applies(
        n_frames, n_vertices, FitOptions.from_dict(options).validate(), tol)
    check_fit_memory(n_frames, n_vertices, settings.job_memory_limit(), tol, tasks=tasks)
    return tasks


def run_cyclic(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
               partial: Partial | None = None) -> dict:
    """Mesh -> loopable swim-cycle clip, or a gait's looping clip of the skinned glTF the mesh came from."""
    from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip

    mesh = _mesh(job, blobs, settings)
    parts = make_cyclic_clip(mesh, CyclicOptions.from_dict(job["params"]["params"]), progress=progress,
                             source=blobs.get(job["mesh"]["blob_key"]))
    frames = int(parts.report.get("frames", 1)) if isinstance(parts.report.get("frames"), int) else 1
    return {"clip": store_clip(parts, blobs, frames, len(mesh.vertices))}


def run_export(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
               partial: Partial | None = None) -> dict:
    """Clip -> animation GLB (quantised, meshopt-compressed, keeping the source mesh's look) in the blob
    store."""
    from pdeanim.clip import open_clip
    from pdeanim.gltf.clipexport import ExportOptions, clip_animation_glb, estimate_export
    from pdeanim.gltf.layout import source_layout

    opts = ExportOptions.from_dict(job["params"]["params"])
    progress(0.0, "export: load clip")
    clip = open_clip(blobs.get(job["clip"]["topology_key"]), blobs.get(job["clip"]["coefficients_key"]),
                     EXPORT_DECODE_BYTES)  # a long clip is evaluated a block of curves at a time
    estimate = estimate_export(clip, opts.fps, settings.max_frames)
    mesh = job.get("mesh") or {}
    data = blobs.get(mesh["blob_key"]) if mesh.get("blob_key") else None
    layout = source_layout(data, mesh.get("filename", ""), clip.faces, clip.n_vertices)
    progress(0.1, f"export: {estimate.frames} frames")
    glb = clip_animation_glb(clip, opts.fps, options=opts.pack(), layout=layout,
                             max_frames=settings.max_frames)
    progress(0.95, "export: store")
    return {"export": {"blob_key": blobs.put(glb), "bytes": len(glb), "layout": layout.source,
                       **estimate.to_dict()}}


def run_window(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
               partial: Partial | None = None) -> dict:
    """One window task of a fit in window tasks (pdeanim_worker.windowtasks)."""
    from .windowtasks import run_window as run

    return run(job, blobs, settings, progress, workdir, partial)


STAGES = {"simulate": run_simulate, "fit": run_fit, "cyclic": run_cyclic, "export": run_export,
          "window": run_window}
