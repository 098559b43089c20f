"""Compression benchmark: the clip against the strongest peers, as files and on the wire (issue 22).

Inputs: every pose sequence (``.npz`` with ``vertices`` (F, V, 3) and ``faces``) of the shared data folder
(read in place, never copied into the repository) and two small low-rank animations made here
(benchmarks/peers_synthetic.py), at rel-RMS 3e-3 and 1e-3 (RMS distance over all frames and vertices /
bounding-box diagonal of frame 0; ``pdeanim.model.metrics.error_summary`` scores every method).

* ``clip``: ``pdeanim fit POSES --target-rel-rms R`` at the CLI's defaults (benchmarks/peers_clip.py);
* ``gltfpack``: positions-only morph GLB, best of ``-cc -vp 8..16``, with and without ``-vpf``, EXT and KHR
  meshopt compression (benchmarks/peers_gltfpack.py);
* ``pca``: k by bisection, quantised, zstd; ``keyframes`` (floor reference): quantised frames, zstd
  (benchmarks/peers_lowrank.py);
* ``dembones``: 8/16/32/64 bones, <= 4 influences, quantised, zstd (benchmarks/peers_dembones.py);
* ``skinned`` (skinned glTF inputs, ``--gltf``): the source's own skeletal animation after ``gltfpack -cc``,
  animation and skin data only, against the clip's coefficients part (benchmarks/peers_skinned.py);
* ``heldout``: every 4th frame fitted at the same target, error at the frames in between, against linear and
  Catmull-Rom interpolation (benchmarks/peers_heldout.py).

Bytes: "file" as stored or served, "wire" = zstd -19 of each file (the clip's two parts included). The wire
ratio (clip / the smallest of gltfpack, PCA and Dem Bones meeting the same target) is the yardstick.
Writes ``results.json``, ``table.md`` and ``pareto-SEQUENCE.png`` into ``--out``.
Run: ``.venv/bin/python benchmarks/compression_peers.py`` (``--quick`` for a few minutes' check).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

BLAS_THREADS = os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
"""Set before numpy loads OpenBLAS (the fits' child processes inherit it): on the shared, loaded 2-core
machine OpenBLAS's second thread made matrix products 3x slower. peers_common sets OMP_WAIT_POLICY for the
same reason."""

import numpy as np  # noqa: E402
import peers_clip  # noqa: E402
import peers_dembones  # noqa: E402
import peers_gltfpack  # noqa: E402
import peers_heldout  # noqa: E402
import peers_lowrank  # noqa: E402
import peers_report  # noqa: E402
import peers_skinned  # noqa: E402
from peers_common import OMP_WAIT_POLICY, ROOT, code_label, log  # noqa: E402
from peers_synthetic import SYNTHETIC  # noqa: E402

METHODS = ("clip", "gltfpack", "pca", "dembones", "skinned", "keyframes", "heldout")
TARGETS = (3e-3, 1e-3)
QUICK_SHARED = ("horse-collapse",)


def find_sequences(data: Path | None) -> Path:
    """The sequence folder: --data, $PDEANIM_SEQUENCES, or shared/data/sequences next to the repository."""
    candidates = [data] if data else []
    if os.environ.get("PDEANIM_SEQUENCES"):
        candidates.append(Path(os.environ["PDEANIM_SEQUENCES"]))
    candidates += [p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)]
    for c in candidates:
        if c and c.is_dir():
            return c
    raise SystemExit("no sequence folder: give --data DIR or set PDEANIM_SEQUENCES")


def load_inputs(args: argparse.Namespace) -> dict[str, Path | str]:
    """name -> the shared .npz, or the name of a synthetic animation, in the order they run."""
    folder = find_sequences(args.data)
    shared = {p.stem: p for p in sorted(folder.glob("*.npz"))}
    gltf = {p.stem: p for p in map(Path, args.gltf.split(","))} if args.gltf else {}
    inputs: dict[str, Path | str] = {**{n: n for n in SYNTHETIC}, **shared, **gltf}
    if args.sequences:
        want = args.sequences.split(",")
        missing = [n for n in want if n not in inputs]
        if missing:
            raise SystemExit(f"no such sequences (in {folder} or synthetic): {', '.join(missing)}")
        return {n: inputs[n] for n in want}
    if args.quick:
        return {n: v for n, v in inputs.items() if isinstance(v, str) or n in QUICK_SHARED}
    return inputs


def frames_of(source: Path | str, work: Path) -> tuple[np.ndarray, np.ndarray, Path]:
    """(frames float64, faces, a file the CLI can fit): shared files and glTF inputs (sampled at 30 fps) in
    place, synthetic ones written."""
    if isinstance(source, Path) and source.suffix.lower() in (".glb", ".gltf"):
        from pdeanim.gltf.read import read_animated_poses

        poses = read_animated_poses(source, fps=30.0)
        return poses.vertices.astype(np.float64), poses.faces, source
    if isinstance(source, Path):
        with np.load(source) as d:
            return d["vertices"].astype(np.float64), d["faces"].astype(np.int32), source
    X, faces = SYNTHETIC[source]()
    path = work / f"{source}.npz"
    np.savez(path, vertices=X.astype(np.float32), faces=faces)
    return X.astype(np.float32).astype(np.float64), faces, path


def run_sequence(name: str, source: Path | str, args: argparse.Namespace) -> list[dict]:
    """Every selected method on one input."""
    work = Path(tempfile.mkdtemp(prefix=f"peers-{name}-"))
    try:
        X, faces, npz = frames_of(source, work)
        log(f"{name}: {X.shape[0]} frames x {X.shape[1]} vertices, {len(faces)} faces")
        q, t, tmo = args.quick, args.targets, args.fit_timeout
        steps = {
            "clip": lambda: peers_clip.method_clip(name, npz, X, t, work, tmo),
            "gltfpack": lambda: peers_gltfpack.method_gltfpack(X, faces, work, tmo, q, args.gltfpack_vp,
                                                               not args.gltfpack_no_vpf),
            "pca": lambda: peers_lowrank.method_pca(X, faces, t, q, args.pca_bits),
            "dembones": lambda: peers_dembones.method_dembones(name, X, faces, args.cache, q,
                                                               args.dembones_bones),
            "skinned": lambda: (peers_skinned.method_skinned(npz, X, work, tmo)
                                if npz.suffix.lower() in (".glb", ".gltf") else []),
            "keyframes": lambda: peers_lowrank.method_keyframes(X, faces, t, q),
            "heldout": lambda: [r for tg in t for r in peers_heldout.stated_protocol(name, X, faces, tg, work,
                                                                                    tmo)]
            + ([] if q else peers_heldout.earlier_protocol(name, X, faces, work, tmo)),
        }
        rows: list[dict] = [{"method": "input", "setting": f"{X.shape[0]} frames x {X.shape[1]} vertices",
                             "frames": int(X.shape[0]), "vertices": int(X.shape[1]),
                             "faces": int(len(faces))}]
        for method in (m for m in METHODS if m in args.methods):
            start = time.perf_counter()
            new = steps[method]()
            rows += new
            log(f"{name}: {method} done in {time.perf_counter() - start:.1f} s ({len(new)} rows)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


def versions() -> str:
    """The peers' tool versions and the measured commit."""
    def npm(pkg: str) -> str:
        p = peers_gltfpack.PEERS_DIR / "node_modules" / pkg / "package.json"
        return json.loads(p.read_text())["version"] if p.exists() else "missing"

    from importlib.metadata import version

    return (f"{code_label()}; gltfpack {npm('gltfpack')}, "
            f"meshoptimizer (npm) {npm('meshoptimizer')}, py-dem-bones {version('py-dem-bones')}, "
            f"zstandard {version('zstandard')}, numpy {np.__version__}; OMP_WAIT_POLICY={OMP_WAIT_POLICY}, "
            f"OPENBLAS_NUM_THREADS={BLAS_THREADS}")


class LoadSampler:
    """The 1-min load average sampled every 15 s in a background thread while the benchmark runs."""

    def __init__(self) -> None:
        import threading

        self.samples = [os.getloadavg()[0]]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(15.0):
            self.samples.append(os.getloadavg()[0])

    def stop(self) -> None:
        """End the sampling."""
        self._stop.set()
        self.samples.append(os.getloadavg()[0])


def write_outputs(results: dict[str, list[dict]], args: argparse.Namespace, head: str) -> str:
    """results.json, table.md and the plots into --out; returns the table text."""
    targets = args.targets
    for name, rows in results.items():
        peers_report.pareto_plot(name, rows, targets, args.out / f"pareto-{name}.png")
    text = "\n\n".join([
        head,
        "In short: the clip's wire bytes (bone count; rel-RMS as a share of the target, rel-max as a "
        "multiple of it) and the smallest peer (gltfpack, PCA, Dem Bones) on the wire at each yardstick, "
        "with the clip's wire ratio to it:",
        peers_report.compact_table(results, targets),
        "Bytes at each rel-RMS target: the clip, and the smallest file of each peer that meets the target "
        "(file / wire bytes; wire = zstd -19 of each file; max = rel-max as a multiple of the target). "
        "Wire ratio = clip wire bytes / the smallest of gltfpack, PCA and Dem Bones on the wire; file ratio "
        "the same with file bytes:",
        peers_report.summary_table(results, targets),
        "Goals of issue 30 per sequence and target (the clip's wire bytes over the smallest peer meeting the "
        "target; rel-max and rel-RMS as multiples of the target; a skinned input's coefficients over its own "
        "gltfpack'd animation; the fit's seconds against the strongest Dem Bones setting's solve):",
        peers_report.goals_table(results, targets),
        "Skinned glTF inputs: the clip's coefficients part (bone layer + residual curves) against the "
        "source's own animation and skin after gltfpack -cc (the mesh counted on neither side):",
        peers_report.skinned_table(results, targets),
        "The project's fits:",
        peers_report.clip_table(results),
        "Held-out frames (rel-RMS / rel-max at the frames left out, to frame 0's bbox diagonal):",
        peers_report.heldout_table(results),
        "Every scored setting:",
        *[peers_report.rows_table(n, r) for n, r in results.items()],
    ])
    (args.out / "table.md").write_text(text + "\n")
    return text


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Command-line options."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "compression-peers",
                    help="output folder (results.json, table.md, plots; default out/compression-peers)")
    ap.add_argument("--data", type=Path, help="sequence folder (default $PDEANIM_SEQUENCES or "
                                              "../shared/data/sequences)")
    ap.add_argument("--sequences", help="comma-separated names (shared .npz stems or "
                                        f"{', '.join(SYNTHETIC)}; default: all)")
    ap.add_argument("--gltf", help="comma-separated skinned (or other animated) glTF files to add as inputs")
    ap.add_argument("--targets", default=",".join(f"{t:g}" for t in TARGETS), help="rel-RMS targets")
    ap.add_argument("--methods", default=",".join(METHODS), help=f"subset of {','.join(METHODS)}")
    ap.add_argument("--quick", action="store_true",
                    help="development run: synthetic inputs + horse-collapse, fewer peer settings, no "
                         "earlier held-out protocol")
    ap.add_argument("--cache", type=Path,
                    default=Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pdeanim-bench",
                    help="cache folder of Dem Bones solves (outside the repository)")
    ap.add_argument("--dembones-bones", help="comma-separated Dem Bones bone counts (default 8,16,32,64,128)")
    ap.add_argument("--pca-bits", help="comma-separated bits of PCA's bases (default 8,10,12,14,16)")
    ap.add_argument("--gltfpack-vp", help="comma-separated -vp bit counts of gltfpack (default 8..16)")
    ap.add_argument("--gltfpack-no-vpf", action="store_true",
                    help="leave out gltfpack's float positions (-vpf: never the smallest at 3e-3 or 1e-3 in "
                         "the 2026-12-02 run of every sequence)")
    ap.add_argument("--fit-timeout", type=float, default=3600.0, help="seconds per fit / gltfpack run")
    ap.add_argument("--merge", help="comma-separated OUT folders of finished runs: write their rows as one "
                                    "table into --out (no run; --sequences orders the inputs)")
    ap.add_argument("--resume", action="store_true", help="keep the inputs already in OUT/results.json")
    args = ap.parse_args(argv)
    args.methods = tuple(m for m in args.methods.split(",") if m)
    unknown = set(args.methods) - set(METHODS)
    if unknown:
        ap.error(f"unknown methods: {', '.join(sorted(unknown))}")
    args.targets = tuple(float(t) for t in args.targets.split(","))
    args.merge = [Path(d) for d in args.merge.split(",")] if args.merge else []
    args.pca_bits = tuple(int(b) for b in args.pca_bits.split(",")) if args.pca_bits else None
    args.gltfpack_vp = tuple(int(b) for b in args.gltfpack_vp.split(",")) if args.gltfpack_vp else None
    if args.dembones_bones:
        args.dembones_bones = tuple(int(b) for b in args.dembones_bones.split(","))
    if "gltfpack" in args.methods and not peers_gltfpack.GLTFPACK_CLI.exists():  # a missing peer flatters
        ap.error(f"{peers_gltfpack.GLTFPACK_CLI} is missing: run ./script/setup (npm ci in benchmarks/peers)")
    return args


def run_record(args: argparse.Namespace, seconds: float, loads: list[float], started: str = "",
               fit: str = "") -> dict:
    """The run's time and load, added to those of the runs that --resume continued (OUT/run.json), with the
    command, the measured code and the tools' versions of each run."""
    path = args.out / "run.json"
    prev = json.loads(path.read_text()) if args.resume and path.exists() else {"seconds": 0.0, "loads": []}
    now = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    run = {"command": " ".join(sys.argv), "started": started, "finished": now, "seconds": seconds,
           "project": fit, "versions": versions()}
    rec = {"seconds": prev["seconds"] + seconds, "loads": prev["loads"] + loads, "finished": now,
           "started": prev.get("started") or started or now, "runs": [*prev.get("runs", []), run]}
    path.write_text(json.dumps(rec))
    return rec


def merge(args: argparse.Namespace) -> int:
    """--merge: the results of several runs (each a finished OUT folder) as one table in --out. The rows of
    each input are joined; a clip or held-out row of a target that an earlier folder has is left out (logged),
    so the folder order picks the clip code shown."""
    results: dict[str, list[dict]] = {}
    records = []
    for folder in args.merge:
        part = json.loads((folder / "results.json").read_text())
        for name, rows in part.items():
            have = results.setdefault(name, [])
            seen = {(r["method"], r.get("target"), r.get("protocol")) for r in have
                    if r.get("method") in ("input", "clip", "heldout")}
            for r in rows:
                key = (r["method"], r.get("target"), r.get("protocol"))
                if r.get("method") in ("input", "clip", "heldout") and key in seen:
                    if r["method"] != "input":
                        log(f"merge: {name} {key} of {folder} left out (an earlier folder has it)")
                    continue
                have.append(r)
        if (folder / "run.json").exists():
            records.append((folder, json.loads((folder / "run.json").read_text())))
    order = args.sequences.split(",") if args.sequences else list(results)
    results = {n: results[n] for n in order if n in results}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    loads = np.array([x for _, r in records for x in r["loads"]])
    parts = []
    for folder, r in records:
        for run in r.get("runs", [{"finished": r["finished"], "seconds": r["seconds"]}]):
            what = f"; `{run['command']}`; {run['project']}; {run['versions']}" if run.get("command") else ""
            parts.append(f"- {folder.name}: {run.get('started', '?')} to {run['finished']}, "
                         f"{run['seconds']:.0f} s{what}")
        if r["loads"]:
            lo, hi = min(r["loads"]), max(r["loads"])
            parts.append(f"  (1-min load {lo:.1f}..{hi:.1f} over that folder's runs)")
    load = (f"1-min load average {loads.min():.1f}..{loads.max():.1f} (mean {loads.mean():.1f}, sampled "
            "every 15 s; shared machine)" if len(loads) else "load not recorded")
    head = (f"Compression peers, {len(args.merge)} output folders merged, {os.cpu_count()} CPUs, {load}. "
            "The runs:\n" + "\n".join(parts))
    print(write_outputs(results, args, head))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run every input, write the outputs, print the tables."""
    args = parse_args(argv)
    if args.merge:
        return merge(args)
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    fit = peers_clip.fit_label()  # refuses unlabelled non-default fit options before any work
    inputs = load_inputs(args)
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, list[dict]] = {}
    if args.resume and (args.out / "results.json").exists():
        results = json.loads((args.out / "results.json").read_text())
    sampler, start = LoadSampler(), time.perf_counter()
    for name, source in inputs.items():
        if name in results:
            continue
        results[name] = run_sequence(name, source, args)
        (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    sampler.stop()
    rec = run_record(args, time.perf_counter() - start, sampler.samples, started, fit)
    load = np.array(rec["loads"])
    head = (f"Compression peers{' (--quick)' if args.quick else ''}, finished {rec['finished']}, "
            f"{rec['seconds']:.0f} s, {os.cpu_count()} CPUs, 1-min load average "
            f"{load.min():.1f}..{load.max():.1f} (mean {load.mean():.1f}, sampled every 15 s; shared "
            f"machine). The project: {fit}. {versions()}.")
    text = write_outputs({n: results[n] for n in inputs if n in results}, args, head)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
