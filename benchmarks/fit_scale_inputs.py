"""Long inputs of the fit-scale benchmark (``fit_scale.py``), made here and cached in ``benchmarks/.cache/``:
poses of a ~34k-vertex spot simulated by ``pdeanim simulate``, and shared sequences tiled in time (ping-pong)
with a smooth, low-frequency perturbation so that no two passes are alike. Nothing from
``/work/shared/data/sequences`` is copied into the repository: the cache folder is gitignored."""

from __future__ import annotations

import json
import os
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / ".cache"
SPOT = ROOT / "tests" / "data" / "spot.obj"
FPS = 30.0
INPUTS_VERSION = 1
"""Bumped when the way an input is made changes, so that stale cached files are not reused."""


@dataclass(frozen=True)
class LongInput:
    """A long input by recipe: ``spot-sim`` (``frames`` of a simulated spot of ``vertices`` vertices) or
    ``tile`` (shared sequence ``source`` ping-ponged to ``frames`` frames, then perturbed)."""

    kind: str
    frames: int
    source: str = ""
    vertices: int = 34_000

    @property
    def name(self) -> str:
        """Short label for tables, e.g. ``spot-sim 34k x 1000`` or ``elephant-gallop tiled x 1000``."""
        if self.kind == "spot-sim":
            return f"spot-sim {self.vertices // 1000}k x {self.frames}"
        return f"{self.source} tiled x {self.frames}"

    @property
    def path(self) -> Path:
        """The cached POSES.npz of this input."""
        if self.kind == "spot-sim":
            return CACHE / f"spot{self.vertices}_sim{self.frames}_v{INPUTS_VERSION}.npz"
        return CACHE / f"{self.source}_pingpong{self.frames}_v{INPUTS_VERSION}.npz"


def find_sequences(data: Path | None) -> Path | None:
    """The folder of the shared sequences: ``data``, else $PDEANIM_SEQUENCES, else ../shared/data/sequences
    next to the repository (as benchmarks/compression_peers.py); None if none of them exists."""
    candidates = [data] if data else []
    if os.environ.get("PDEANIM_SEQUENCES"):
        candidates.append(Path(os.environ["PDEANIM_SEQUENCES"]))
    candidates += [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
    return next((c for c in candidates if c.is_dir()), None)


def parse_long_input(text: str) -> LongInput:
    """``spot-sim:FRAMES[:VERTICES]`` or ``SEQUENCE:FRAMES`` (a file stem of the shared sequences)."""
    head, _, rest = text.partition(":")
    parts = rest.split(":") if rest else []
    if not parts or not all(p.isdigit() and int(p) > 1 for p in parts):
        raise ValueError(f"long input {text!r}: use spot-sim:FRAMES[:VERTICES] or SEQUENCE:FRAMES")
    if head == "spot-sim":
        return LongInput("spot-sim", int(parts[0]), vertices=int(parts[1]) if len(parts) > 1 else 34_000)
    if len(parts) != 1:
        raise ValueError(f"long input {text!r}: a tiled sequence takes one number, its frame count")
    return LongInput("tile", int(parts[0]), source=head)


def pingpong_index(n_source: int, n_frames: int) -> np.ndarray:
    """(n_frames,) source frame of each output frame: 0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... (no frame is
    repeated at a turn, so the motion reverses without a pause)."""
    if n_source < 2:
        return np.zeros(n_frames, dtype=np.int64)
    period = 2 * (n_source - 1)
    k = np.arange(n_frames) % period
    return np.where(k < n_source, k, period - k)


def perturbation(rest: np.ndarray, times: np.ndarray, amplitude: float, seed: int = 0) -> np.ndarray:
    """(len(times), V, 3) float32 smooth displacement: a sum of three travelling waves of periods 4-9 s and
    wavelengths of 1-2 rest diagonals, each along its own direction, of RMS about ``amplitude`` x the rest
    pose's bounding-box diagonal. Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
    centred = (rest - rest.mean(axis=0)) / diag  # (V, 3), about unit size
    out = np.zeros((len(times), len(rest), 3), np.float32)
    for freq, wavelength in ((1 / 9, 2.0), (1 / 6, 1.5), (1 / 4, 1.0)):
        direction, normal = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        phase = rng.uniform(0, 2 * np.pi)
        space = 2 * np.pi * (centred @ normal) / wavelength  # (V,)
        wave = np.sin(2 * np.pi * freq * np.asarray(times)[:, None] + space[None, :] + phase)  # (F, V)
        out += (amplitude * diag * np.sqrt(2 / 3) * wave[..., None] * direction).astype(np.float32)
    return out


def tiled_poses(source: Path, n_frames: int, amplitude: float = 0.005, seed: int = 0,
                chunk: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n_frames, V, 3) float32, faces) of ``source`` ping-ponged to ``n_frames`` frames plus
    :func:`perturbation`, built ``chunk`` frames at a time."""
    with np.load(source) as data:
        frames, faces = np.asarray(data["vertices"], np.float32), np.asarray(data["faces"], np.int32)
    index = pingpong_index(len(frames), n_frames)
    times = np.arange(n_frames) / FPS
    out = np.empty((n_frames, frames.shape[1], 3), np.float32)
    for start in range(0, n_frames, chunk):
        sl = slice(start, min(start + chunk, n_frames))
        out[sl] = frames[index[sl]] + perturbation(frames[0], times[sl], amplitude, seed)
    return out, faces


def decimated_spot(n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Spot (tests/data/spot.obj, 2,930 vertices) subdivided twice by trimesh (46,850 vertices), then
    quadric-decimated by fast-simplification to ``n_vertices`` (closed: 2 V - 4 faces). Decimation keeps
    well-shaped triangles, so curve extraction finds curves of ~7 points (splitting the largest faces at their
    centroids instead gave slivers and curves of 2 points)."""
    import fast_simplification
    import trimesh

    from pdeanim.mesh.io import load_mesh

    base = load_mesh(SPOT)
    fine = trimesh.Trimesh(base.vertices, base.faces, process=False).subdivide().subdivide()
    v, f = fast_simplification.simplify(np.asarray(fine.vertices, np.float32),
                                        np.asarray(fine.faces, np.int32), target_count=2 * n_vertices - 4)
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def spot_scene(n_frames: int) -> dict:
    """A scene that keeps moving over the whole clip: the feet pinned, the head driven through a nod or a
    shake every 2 s (keyframes alternate between axes), the body swaying under gravity in between."""
    n_keys = max(2, int(round(n_frames / FPS / 2)))
    keys = [{"t": (k + 1) / n_keys, "rotate": [1, 0, 0, 20] if k % 2 == 0 else [0, 1, 0, -20 if k % 4 == 1
                                                                                   else 20]}
            for k in range(n_keys)]
    return {"pins": [{"box": [0, 0, 0, 1, 0.12, 1], "relative": True}],
            "drivers": [{"region": {"box": [0, 0, 0.8, 1, 1, 1], "relative": True}, "keyframes": keys}]}


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A Wavefront OBJ of the mesh (6 decimals)."""
    with open(path, "w") as fh:
        np.savetxt(fh, vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(fh, faces + 1, fmt="f %d %d %d")


def make_spot_sim(item: LongInput, console: list[str]) -> dict:
    """Simulate the decimated spot with ``pdeanim simulate`` (a child process) into ``item.path``; what the
    simulation printed and its wall time."""
    mesh = CACHE / f"spot{item.vertices}_v{INPUTS_VERSION}.obj"
    if not mesh.exists():
        write_obj(mesh, *decimated_spot(item.vertices))
    scene = CACHE / f"spot_scene{item.frames}_v{INPUTS_VERSION}.json"
    scene.write_text(json.dumps(spot_scene(item.frames)))
    tmp = item.path.with_suffix(".partial.npz")
    cmd = [*console, "simulate", str(mesh), "--frames", str(item.frames), "--out", str(tmp), "--scene",
           str(scene), "--cache-dir", str(CACHE / "tets"), "--quiet"]
    started = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}:\n{done.stdout}\n{done.stderr}")
    tmp.rename(item.path)
    return {"made": "pdeanim simulate", "seconds": round(time.perf_counter() - started, 1),
            "said": done.stdout.strip()}


def make_tiled(item: LongInput, sequences: Path) -> dict:
    """Write the tiled, perturbed sequence to ``item.path`` (the source read from ``sequences``)."""
    started = time.perf_counter()
    vertices, faces = tiled_poses(sequences / f"{item.source}.npz", item.frames)
    tmp = item.path.with_suffix(".partial.npz")
    with open(tmp, "wb") as fh:
        np.savez(fh, vertices=vertices, faces=faces)
    tmp.rename(item.path)
    return {"made": "ping-pong + perturbation", "seconds": round(time.perf_counter() - started, 1)}


def ensure_input(item: LongInput, console: list[str], sequences: Path | None) -> dict:
    """Make ``item`` unless it is cached; how it was made (``cached`` when it was already there)."""
    if item.path.exists():
        return {"made": "cached"}
    CACHE.mkdir(parents=True, exist_ok=True)
    if item.kind == "spot-sim":
        return make_spot_sim(item, console)
    if sequences is None:
        raise SystemExit(f"{item.name} needs the shared sequences: give --data DIR or set PDEANIM_SEQUENCES")
    return make_tiled(item, sequences)


def input_shape(path: Path) -> tuple[int, int]:
    """(frames, vertices) of a POSES.npz from its npy header, without reading the frames."""
    import zipfile

    from numpy.lib import format as npy_format

    with zipfile.ZipFile(path) as zf, zf.open("vertices.npy") as fh:
        version = npy_format.read_magic(fh)
        read = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
        shape = read(fh)[0]
    return int(shape[0]), int(shape[1])
