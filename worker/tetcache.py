"""Tetrahedral meshes shared through the blob store, so every worker on every machine simulates a given
mesh + parameters on the same tets (fTetWild's output is not bit-reproducible between runs).

The blob key is ``tets-<cache key>`` with the key of :func:`pdeanim.sim.tetra.cache_key` (mesh content,
tet parameters, pytetwild version). Before a simulation the worker downloads that blob into a cache
directory private to the attempt; if it is absent, it tetrahedralizes and uploads with a conditional
write (first writer wins); a loser of that race switches to the winner's tets before simulating.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

from pdeanim_service.store.blobs import BlobNotFound, BlobStore

log = logging.getLogger("pdeanim.worker")
BLOB_PREFIX = "tets-"


def tet_blob_key(cache_key: str) -> str:
    """Blob key of the shared tets of one cache key."""
    return f"{BLOB_PREFIX}{cache_key}"


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def shared_tets(mesh, target_tets: int, blobs: BlobStore, cache_dir: Path,  # noqa: ANN001 - SurfaceMesh
                workdir: Path | None = None) -> str:
    """Put the blob store's tets for (mesh, target_tets) into ``cache_dir`` as ``tets-<key>.npz`` (the file
    :func:`pdeanim.sim.tetra.tetrahedralize` reads), making and publishing them if nobody has yet.
    Returns the cache key, which the job records."""
    from pdeanim.sim.tetra import TetParams, cache_key, tetrahedralize

    params = TetParams(target_tets=target_tets)  # as pdeanim.sim.simulate.simulate_mesh builds them
    key = cache_key(mesh, params)
    local, blob = Path(cache_dir) / f"tets-{key}.npz", tet_blob_key(key)
    try:
        _write_atomic(local, blobs.get(blob))
        return key
    except BlobNotFound:
        pass
    local.unlink(missing_ok=True)
    tetrahedralize(mesh, params, cache_dir=cache_dir, workdir=workdir)
    if not blobs.put_if_absent(local.read_bytes(), blob):
        log.warning("another worker published tets %s first; using those", key)
        _write_atomic(local, blobs.get(blob))
    return key


def check_only_shared(cache_dir: Path, key: str) -> None:
    """Warn when the simulation tetrahedralized under another key than :func:`shared_tets` prepared (the
    simulation's TetParams changed): its tets were then not shared between workers."""
    others = sorted(p.name for p in Path(cache_dir).glob("tets-*.npz") if p.name != f"tets-{key}.npz")
    if others:
        log.warning("the simulation made its own tets %s instead of the shared tets-%s.npz: results of this "
                    "mesh are not reproducible across workers", others, key)
