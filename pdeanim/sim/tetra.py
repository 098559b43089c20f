"""Tetrahedralize a surface mesh with fTetWild (pytetwild 0.2.3) at a target tet count, with an on-disk cache.

fTetWild's output is not bit-reproducible, so results are cached by (mesh content hash, parameters, pytetwild
version): a repeated job reuses the same tets and hence stays deterministic. fTetWild runs in a child process
inside a private temporary directory (it writes ``__tracked_surface.stl`` into its working directory).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from importlib.metadata import version
from pathlib import Path

import numpy as np

from ..errors import ParameterError, TetrahedralizationError
from ..mesh.io import SurfaceMesh
from .decimate import decimate, decimation_method
from .tetmesh import TetMesh, clean_tet_mesh

TETS_PER_EDGE_CUBE = 10.0
"""Measured on spot.obj with fTetWild: about 10 tets per ideal-edge-length cube of enclosed volume."""
TIMEOUT_S = 600
FACES_PER_TET = 2.0
"""Surface faces kept for fTetWild per target tet. A mesh of N tets has O(N^(2/3)) boundary faces, so finer
surface detail is lost in the tets anyway and only costs fTetWild time and memory: on a 41k-vertex sphere,
quadric decimation to this budget brings tetrahedralization at 3000 tets to a few seconds
(benchmarks/tetrahedralize_large.py)."""
MIN_SURFACE_FACES = 2000
DECIMATION = "quadric-budget-1"
"""Changes whenever the surface handed to fTetWild changes for the same input, so cached tets are not
mixed."""


@dataclass(frozen=True)
class TetParams:
    """How to tetrahedralize: a target tet count, the surface budget before decimation, fTetWild threads."""

    target_tets: int = 5000
    max_surface_faces: int = 20_000
    threads: int = 1
    retries: int = 1

    def __post_init__(self) -> None:
        if not 50 <= self.target_tets <= 2_000_000:
            raise ParameterError(f"target_tets must be in [50, 2000000], got {self.target_tets}")
        if self.max_surface_faces < 100 or self.threads < 0 or self.retries < 0:
            raise ParameterError("max_surface_faces must be >= 100, threads and retries >= 0")


def enclosed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed surface (divergence theorem); falls back to half the bbox volume."""
    p = vertices[faces]
    vol = abs(float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0)
    box = float(np.prod(np.ptp(vertices, axis=0)))
    return vol if 1e-6 * box < vol <= box else 0.5 * box


def surface_budget(target_tets: int, max_faces: int) -> int:
    """Faces of the surface given to fTetWild: FACES_PER_TET per target tet, within [MIN_SURFACE_FACES,
    max_faces]; any accepted mesh is decimated to this first, so tetrahedralization time and memory depend on
    the tet budget, not on the mesh's resolution."""
    return int(min(max_faces, max(MIN_SURFACE_FACES, FACES_PER_TET * target_tets)))


def edge_length_for(volume: float, target_tets: int) -> float:
    """Ideal edge length that gives about ``target_tets`` tets in ``volume`` (the measured rule above)."""
    return (TETS_PER_EDGE_CUBE * volume / target_tets) ** (1.0 / 3.0)


def cache_key(mesh: SurfaceMesh, params: TetParams) -> str:
    """Hex key of (mesh content, parameters, pytetwild version, the surface-budget rule, and the decimation
    method with its library version when the surface is decimated) under which a result is cached."""
    budget = surface_budget(params.target_tets, params.max_surface_faces)
    reduced = decimation_method() if len(mesh.faces) > budget else None
    blob = json.dumps({"mesh": mesh.content_hash, "params": asdict(params), "pytetwild": version("pytetwild"),
                       "decimation": DECIMATION, "decimation_method": reduced}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def tet_surface(mesh: SurfaceMesh, params: TetParams) -> tuple[np.ndarray, np.ndarray]:
    """The surface handed to fTetWild: ``mesh`` decimated to :func:`surface_budget` faces when larger."""
    return decimate(mesh.vertices, mesh.faces, surface_budget(params.target_tets, params.max_surface_faces))


def tetrahedralize(mesh: SurfaceMesh, params: TetParams | None = None, cache_dir: Path | None = None,
                   workdir: Path | None = None) -> TetMesh:
    """Tets filling ``mesh`` (decimated first if large), about ``params.target_tets`` of them, cached on
    disk."""
    params = params or TetParams()
    cached = Path(cache_dir) / f"tets-{cache_key(mesh, params)}.npz" if cache_dir else None
    if cached is not None and cached.is_file():
        with np.load(cached, allow_pickle=False) as data:
            return TetMesh(data["points"], data["tets"])
    vertices, faces = tet_surface(mesh, params)
    used = vertices[np.unique(faces)]  # vertices no face uses must not make a flat surface look solid
    diagonal = float(np.linalg.norm(np.ptp(used, axis=0)))
    if float(np.ptp(used, axis=0).min()) <= 1e-6 * diagonal:
        raise TetrahedralizationError(
            "the surface is flat (no thickness along one axis): it encloses no volume"
        )
    length = edge_length_for(enclosed_volume(vertices, faces), params.target_tets)
    result = None
    for attempt in range(params.retries + 1):
        result = run_tetwild(vertices, faces, length / diagonal, params.threads, workdir)
        ratio = result.n_tets / params.target_tets
        if 0.6 <= ratio <= 1.6 or attempt == params.retries:
            break
        length *= ratio ** (1.0 / 3.0)
    if cached is not None:
        save_atomically(cached, result)
    return result


def run_tetwild(vertices: np.ndarray, faces: np.ndarray, edge_fac: float, threads: int,
                workdir: Path | None) -> TetMesh:
    """One fTetWild call in a child process and a private directory; TetrahedralizationError on failure."""
    edge_fac = float(np.clip(edge_fac, 1e-3, 0.5))
    options = {"edge_length_fac": edge_fac, "epsilon": float(np.clip(edge_fac / 5.0, 1e-3, 2e-2)),
               "num_threads": int(threads)}
    with tempfile.TemporaryDirectory(prefix="pdeanim-tet-", dir=workdir) as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, vertices=vertices, faces=faces, options=np.array(json.dumps(options)))
        env = dict(os.environ, OMP_NUM_THREADS=str(max(threads, 1)))
        try:
            proc = subprocess.run([sys.executable, "-m", "pdeanim.sim.tetwild_run", str(src), str(dst)],
                                  cwd=tmp, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired as exc:
            raise TetrahedralizationError(f"fTetWild took longer than {TIMEOUT_S} s") from exc
        if proc.returncode != 0 or not dst.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:]
            if "bad_alloc" in (proc.stderr or ""):
                raise TetrahedralizationError(
                    "fTetWild ran out of memory (the job's memory limit): lower target_tets"
                )
            how = (
                f"crashed with signal {-proc.returncode}"
                if proc.returncode < 0
                else f"exited {proc.returncode}"
            )
            raise TetrahedralizationError(
                f"fTetWild {how} on this surface (non-manifold or degenerate input?)"
                + (f": {tail[0][:300]}" if tail else "")
            )
        with np.load(dst, allow_pickle=False) as data:
            return clean_tet_mesh(data["points"], data["tets"])


def save_atomically(path: Path, tets: TetMesh) -> None:
    """Write the cache file under a temporary name then rename, so readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    with os.fdopen(fd, "wb") as fh:
        np.savez(fh, points=tets.points, tets=tets.tets)
    os.replace(tmp, path)
