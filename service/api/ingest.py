"""What validating an upload does, run in the validator's child process
(:mod:`pdeanim_service.api.validator`): read
the file from disk with the library's readers under the configured limits, and hand back only small results
(stats, or the path of the canonical POSES.npz written next to the upload), never the arrays."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from pdeanim.errors import InputError, PosesInputError

from ..settings import Settings


class MeshGone(InputError):
    """The mesh that uploaded poses belong to was deleted while they were being validated."""

    code = "not_found"
    status = 404


def mesh_stats(path: str, filename: str, settings_json: str) -> dict:
    """Stats of an uploaded mesh file (vertices, faces, components, watertight, bbox), or an InputError."""
    from pdeanim.mesh.io import MeshLimits, load_mesh

    settings = Settings.model_validate_json(settings_json)
    limits = MeshLimits(settings.max_upload_bytes, settings.max_vertices, settings.max_faces,
                        settings.gltf_limits())
    return load_mesh(Path(path), filename=filename, limits=limits).stats()


def _read(path: Path, filename: str, settings: Settings, fps: float, animation: str | None):  # noqa: ANN202
    """Poses of an uploaded .npz or animated glTF under the settings' limits (pdeanim Poses)."""
    from pdeanim.poses import PoseLimits, load_poses_npz

    limits = PoseLimits(max_frames=settings.max_frames, max_vertices=settings.max_vertices,
                        max_bytes=settings.max_pose_bytes)
    suffix = Path(filename).suffix.lower()
    if suffix == ".npz":
        if animation is not None:
            raise PosesInputError("animation applies to glTF uploads only; this is a .npz")
        return load_poses_npz(path, limits), limits
    if suffix in (".glb", ".gltf"):
        from pdeanim.gltf.read import read_animated_poses

        poses = read_animated_poses(path, fps=fps, limits=limits, animation=animation,
                                    gltf_limits=settings.gltf_limits())
        return poses, limits
    raise PosesInputError(f"unsupported poses file type {suffix or filename!r}: use .npz or .glb")


def _mesh_faces(mesh: dict[str, Any], settings: Settings) -> np.ndarray:
    """The faces of the stored mesh the poses belong to (read from the blob store in this process)."""
    from pdeanim.mesh.io import MeshLimits, load_mesh

    from ..store.blobs import BlobNotFound, open_blob_store

    try:
        data = open_blob_store(settings).get(mesh["blob_key"])
    except BlobNotFound:  # its last row went (a mesh's blob is stored as long as its row exists)
        raise MeshGone(f"mesh {mesh['id']!r} not found (it was deleted while the poses were "
                       "uploaded)") from None
    limits = MeshLimits(max(settings.max_upload_bytes, len(data)), settings.max_vertices, settings.max_faces,
                        settings.gltf_limits())
    return load_mesh(data, filename=mesh["filename"], limits=limits).faces


def poses_file(path: str, filename: str, mesh: dict[str, Any], settings_json: str, fps: float,
               animation: str | None, out_prefix: str) -> tuple[str, int, dict]:
    """Validate uploaded poses of ``mesh`` (id, n_vertices, blob_key, filename) and write them as a
    canonical POSES.npz in the scratch directory, named with ``out_prefix`` (the API process's scratch
    prefix, so only its death makes the file stale): (its path, frames, the row's meta)."""
    from pdeanim.poses import make_poses, save_poses

    settings = Settings.model_validate_json(settings_json)
    poses, limits = _read(Path(path), filename, settings, fps, animation)
    if poses.n_vertices != mesh["n_vertices"]:
        raise PosesInputError(f"poses have {poses.n_vertices} vertices but mesh {mesh['id']} has "
                              f"{mesh['n_vertices']}")
    if poses.faces.size == 0:
        poses = make_poses(poses.vertices, _mesh_faces(mesh, settings), poses.times, poses.meta, limits)
    meta: dict = {"filename": filename[:255]}
    used = (poses.meta or {}).get("animation")
    if isinstance(used, dict):
        meta["animation"] = {"index": used.get("index"), "name": used.get("name")}
    fd, out = tempfile.mkstemp(dir=settings.tmp_dir(), prefix=out_prefix, suffix=".npz")
    os.close(fd)
    try:
        save_poses(out, poses)
    except BaseException:
        Path(out).unlink(missing_ok=True)
        raise
    return out, poses.n_frames, meta
