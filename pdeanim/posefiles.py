"""Poses from a file of any supported kind: POSES.npz (:mod:`pdeanim.poses`) or an animated glTF
(:mod:`pdeanim.gltf.read`). A module of its own so that ``poses`` and ``gltf.read`` do not import each
other."""

from __future__ import annotations

from pathlib import Path

from .errors import PosesInputError
from .gltf.read import read_animated_poses
from .poses import DEFAULT_FPS, PoseLimits, Poses, load_poses_npz


def load_poses(path: str | Path, fps: float = DEFAULT_FPS, limits: PoseLimits | None = None,
               animation: int | str | None = None) -> Poses:
    """Read poses from a .npz or an animated .glb/.gltf (sampled at ``fps``; ``animation`` by name or index,
    default the first; ``meta["animation"]`` says which was used)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        if animation is not None:
            raise PosesInputError(f"an animation ({animation!r}) can only be chosen in glTF input, "
                                  f"not in {path.name}")
        return load_poses_npz(path, limits)
    if suffix in (".glb", ".gltf"):
        return read_animated_poses(path, fps=fps, limits=limits, animation=animation)
    raise PosesInputError(f"unsupported poses file type {suffix!r}: use .npz, .glb or .gltf")
