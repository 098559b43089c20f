"""Poses from a file of any supported kind: POSES.npz (:mod:`pdeanim.poses`) or an animated glTF
(:mod:`pdeanim.gltf.read`). A module of its own so that ``poses`` and ``gltf.read`` do not import each
other."""

from __future__ import annotations

from pathlib import Path

from .errors import PosesInputError
from .gltf.read import read_animated_poses
from .poses import DEFAULT_FPS, PoseLimits, Poses, load_poses_npz, load_poses_npz_mapped


def load_poses(path: str | Path, fps: float = DEFAULT_FPS, limits: PoseLimits | None = None,
               animation: int | str | None = None, map_over: int | None = None) -> Poses:
    """Read poses from a .npz or an animated .glb/.gltf (sampled at ``fps``; ``animation`` by name or index,
    default the first; ``meta["animation"]`` says which was used). ``map_over``: a .npz of more frame-vertex
    values than this has its vertices mapped from a file (:func:`pdeanim.poses.load_poses_npz_mapped`), not
    held in memory."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        if animation is not None:
            raise PosesInputError(f"an animation ({animation!r}) can only be chosen in glTF input, "
                                  f"not in {path.name}")
        if map_over is not None and _npz_values(path) > map_over:
            return load_poses_npz_mapped(path, limits)
        return load_poses_npz(path, limits)
    if suffix in (".glb", ".gltf"):
        return read_animated_poses(path, fps=fps, limits=limits, animation=animation)
    raise PosesInputError(f"unsupported poses file type {suffix!r}: use .npz, .glb or .gltf")


def _npz_values(path: Path) -> int:
    """Frames x vertices of a POSES.npz's ``vertices`` from its npy header (0 where it cannot be read: the
    ordinary reader then says what is wrong)."""
    import zipfile

    from numpy.lib import format as npy_format

    try:
        with zipfile.ZipFile(path) as zf, zf.open("vertices.npy") as fh:
            version = npy_format.read_magic(fh)
            read = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
            shape = read(fh)[0]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, NotImplementedError, RuntimeError):
        return 0
    return int(shape[0]) * int(shape[1]) if len(shape) == 3 else 0
