"""Fit speed and memory against frames x vertices (issue 21): frame-vertices per second, wall time and peak
memory of ``pdeanim fit`` with the CLI's defaults, each fit in a fresh child process.

    .venv/bin/python benchmarks/fit_scale.py [--quick] [--parts a,b,c] [--repeats N] [--json PATH]

(a) every sequence of ../shared/data/sequences (``--data``) at rel-RMS 3e-3 and 1e-3 (medians of 3 runs);
(b) long inputs made here and cached in benchmarks/.cache/ (gitignored): a ~34k-vertex spot simulated by
    ``pdeanim simulate`` for 1,000 frames, and shared sequences ping-ponged in time with a smooth
    perturbation, up to ~42 M frame-vertices (1 run each);
(c) one long input as a fit job through the service (``pdeanim serve --with-workers N``, the embedded
    default), with 1 and then 2 job workers: the job's wall time, both in one run.
Peak memory is the child's peak resident set (``ru_maxrss`` from ``wait4`` on that child: the kernel's VmHWM
of the process). Frame-vertices per second divide frames x vertices by the wall time of the whole ``pdeanim
fit`` process (reading the poses, fitting, writing the clip); "fit s" is the report's own ``timings_s.total``.
Prints the load average and the date at the start and end of each part, and the issue's goals beside the
figures, met or not.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.fit_scale_inputs import (  # noqa: E402
    LongInput,
    ensure_input,
    find_sequences,
    input_shape,
    parse_long_input,
)
from benchmarks.fit_scale_report import goal_lines, markdown_table, service_table  # noqa: E402

CONSOLE = [sys.executable, "-m", "pdeanim_service.cli"]
LONG_INPUTS = "spot-sim:1000,elephant-gallop:250,elephant-gallop:500,elephant-gallop:1000,samba:1000"
QUICK_SEQUENCES = "AnimatedMorphSphere,horse-collapse"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line; ``--quick`` fills what was not given with a small subset."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="a subset for development: 2 sequences at 3e-3 (1 run each), one tiled input of "
                         "100 frames for (b) and (c)")
    ap.add_argument("--parts", default="a,b,c", type=parse_parts, help="which parts to run (a,b,c)")
    ap.add_argument("--repeats", type=int, help="runs per row, median reported (default 3 for the "
                    "sequences, 1 for the long inputs)")
    ap.add_argument("--json", type=Path, help="also write every figure to this JSON file")
    ap.add_argument("--data", type=Path, help="folder of the shared sequences (default $PDEANIM_SEQUENCES or "
                    "../shared/data/sequences)")
    ap.add_argument("--sequences", help="comma-separated stems of (a) (default: every .npz of the folder)")
    ap.add_argument("--targets", type=parse_floats, help="rel-RMS targets of (a) (default 3e-3,1e-3)")
    ap.add_argument("--long-inputs", help=f"inputs of (b), spot-sim:FRAMES[:VERTICES] or SEQUENCE:FRAMES "
                    f"(default {LONG_INPUTS})")
    ap.add_argument("--long-targets", type=parse_floats, default=[3e-3], help="rel-RMS targets of (b)")
    ap.add_argument("--service-input", help="input of (c) (default spot-sim:1000)")
    ap.add_argument("--service-workers", type=parse_ints, default=[1, 2], help="job workers of (c)")
    ap.add_argument("--service-env", action="append", default=[], metavar="PDEANIM_X=VALUE",
                    help="an extra documented setting for the service of (c)")
    ap.add_argument("--pca", action="store_true", help="(b): also size quantised PCA of each long input at "
                    "the clip's error (issue 31's goal: the clip at most 0.6x its wire bytes)")
    ap.add_argument("--timeout", type=float, default=3600, help="seconds before a fit child or job is "
                    "stopped (recorded as timed out)")
    args = ap.parse_args(argv)
    if args.repeats is not None and args.repeats < 1:
        ap.error("--repeats must be >= 1")
    args.data = find_sequences(args.data)
    if "a" in args.parts and args.data is None:
        ap.error("part a needs the shared sequences: give --data DIR or set PDEANIM_SEQUENCES")
    if args.sequences or args.quick:
        args.sequences = (args.sequences or QUICK_SEQUENCES).split(",")
    else:
        args.sequences = sorted(p.stem for p in args.data.glob("*.npz")) if args.data else []
    missing = [s for s in args.sequences if "a" in args.parts and not (args.data / f"{s}.npz").exists()]
    if missing:
        ap.error(f"no {', '.join(missing)} in {args.data}")
    args.targets = args.targets or ([3e-3] if args.quick else [3e-3, 1e-3])
    try:
        args.long_inputs = [parse_long_input(t) for t in
                            (args.long_inputs or ("elephant-gallop:100" if args.quick else LONG_INPUTS))
                            .split(",")]
        args.service_input = parse_long_input(args.service_input or (
            "elephant-gallop:100" if args.quick else "spot-sim:1000"))
    except ValueError as exc:
        ap.error(str(exc))
    args.seq_repeats = args.repeats or (1 if args.quick else 3)
    args.long_repeats = args.repeats or 1
    return args


def parse_parts(text: str) -> list[str]:
    """``a,b,c`` -> ["a", "b", "c"]; anything else is an argparse error."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    if not parts or any(p not in ("a", "b", "c") for p in parts):
        raise argparse.ArgumentTypeError(f"parts are a, b and c, got {text!r}")
    return parts


def parse_floats(text: str) -> list[float]:
    """``3e-3,1e-3`` -> [0.003, 0.001] (positive numbers)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected numbers, got {text!r}") from exc
    if not all(v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"expected positive numbers, got {text!r}")
    return values


def parse_ints(text: str) -> list[int]:
    """``1,2`` -> [1, 2] (positive integers)."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected integers, got {text!r}") from exc
    if not all(v >= 1 for v in values):
        raise argparse.ArgumentTypeError(f"expected integers >= 1, got {text!r}")
    return values


def now() -> str:
    """The date and time in UTC, to the second."""
    return datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def loads() -> list[float]:
    """The 1, 5 and 15 minute load averages, rounded."""
    return [round(x, 2) for x in os.getloadavg()]


@contextmanager
def part_log(name: str, record: dict) -> Iterator[None]:
    """Print (and keep in ``record``) the date and load average at the start and end of a part."""
    record.update(started=now(), load_start=loads())
    print(f"\n== part {name}: start {record['started']}, load average {record['load_start']}", flush=True)
    t0 = time.perf_counter()
    try:
        yield
    finally:
        record.update(ended=now(), load_end=loads(), seconds=round(time.perf_counter() - t0, 1))
        print(f"== part {name}: end {record['ended']} ({record['seconds']:.0f} s), load average "
              f"{record['load_end']}", flush=True)


def run_fit_cli(poses: Path, target: float, out: Path, timeout: float) -> dict:
    """One ``pdeanim fit POSES --out CLIP --target-rel-rms T`` in a fresh child: its exit code, wall time,
    peak resident memory (``ru_maxrss`` of the child, from ``wait4``) and the clip's report (None if none)."""
    out.unlink(missing_ok=True)
    cmd = [*CONSOLE, "fit", str(poses), "--out", str(out), "--target-rel-rms", repr(target), "--quiet"]
    with tempfile.TemporaryFile("w+") as log:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        timer = threading.Timer(timeout, proc.kill)
        timer.start()
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        timer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        said = log.read()
    report = None
    if out.exists():
        from pdeanim.clip import read_clip_file

        report = read_clip_file(out).report
    return {"rc": proc.returncode, "wall_s": wall, "peak_bytes": usage.ru_maxrss * 1024, "report": report,
            "timed_out": wall >= timeout and proc.returncode < 0, "said": said[-2000:]}


def summarise(runs: list[dict]) -> dict:
    """One row's figures from repeated runs of the same fit: medians of wall, fit time and peak memory; the
    errors, bytes and choices of the last run that wrote a clip (the fit is deterministic)."""
    walls = [r["wall_s"] for r in runs]
    peaks = [r["peak_bytes"] for r in runs]
    reports = [r["report"] for r in runs if r["report"]]
    row = {"runs": len(runs), "wall_s": statistics.median(walls), "wall_all_s": [round(w, 2) for w in walls],
           "peak_mib": statistics.median(peaks) / 2**20, "peak_all_mib": [round(p / 2**20) for p in peaks],
           "rc": [r["rc"] for r in runs], "timed_out": any(r["timed_out"] for r in runs)}
    if not reports:
        return {**row, "met": False, "fit_s": None, "rel_rms": None, "rel_max": None, "bytes": None,
                "windowed": None, "segments": None}
    rep = reports[-1]
    sizes = rep.get("sizes", {})
    timings = [r["timings_s"]["total"] for r in reports if "total" in r.get("timings_s", {})]
    return {**row, "met": bool(rep.get("target_met")),
            "fit_s": statistics.median(timings) if timings else None,
            "rel_rms": rep.get("rel_rms"), "rel_max": rep.get("rel_max"),
            "bytes": sizes.get("topology_bytes", 0) + sizes.get("coefficients_bytes", 0),
            "windowed": bool(rep.get("windowed")), "segments": rep.get("segments"),
            "timings_s": {k: round(v, 2) for k, v in rep.get("timings_s", {}).items()},
            "trials": len(rep.get("rate_control") or [])}


def fit_row(name: str, path: Path, target: float, repeats: int, timeout: float, work: Path) -> dict:
    """Fit ``path`` ``repeats`` times at ``target``; the row (printed as soon as it is measured)."""
    frames, vertices = input_shape(path)
    load = loads()[0]
    runs = [run_fit_cli(path, target, work / "fit.clip", timeout) for _ in range(repeats)]
    row = {"input": name, "frames": frames, "vertices": vertices, "frame_vertices": frames * vertices,
           "target": target, "load": load, "load_after": loads()[0], **summarise(runs)}
    row["fv_per_s"] = row["frame_vertices"] / row["wall_s"]
    if any(rc not in (0, 3) for rc in row["rc"]):
        print(f"   {name}: pdeanim fit exited {row['rc']}: {runs[-1]['said'][-600:]}", flush=True)
    print(markdown_table([row], header=False), flush=True)
    return row


def part_sequences(args: argparse.Namespace, work: Path) -> list[dict]:
    """(a) every chosen shared sequence at every target."""
    print(markdown_table([], header=True), flush=True)
    return [fit_row(stem, args.data / f"{stem}.npz", target, args.seq_repeats, args.timeout, work)
            for stem in args.sequences for target in args.targets]


def prepare(item: LongInput, sequences: Path | None) -> None:
    """Make a long input unless cached, saying how long it took."""
    made = ensure_input(item, CONSOLE, sequences)
    if made["made"] != "cached":
        print(f"   made {item.name} ({made['made']}, {made['seconds']:.0f} s, load {loads()[0]})"
              + (f": {made['said']}" if made.get("said") else ""), flush=True)


PCA_GOAL = 0.6
"""Issue 31: a long input's clip at most this multiple of quantised PCA's wire bytes at the same error."""


def pca_peer(row: dict, path: Path, clip: Path) -> None:
    """The smallest quantised PCA file (benchmarks/peers_lowrank.py) at the clip's own decoded rel-RMS, its
    wire bytes beside the clip's (both zstd -19 as served), added to ``row`` and printed with the goal."""
    import numpy as np

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from peers_common import wire_bytes
    from peers_lowrank import method_pca

    if not row.get("rel_rms") or not clip.exists():
        return
    with np.load(path) as d:
        X, faces = np.asarray(d["vertices"], np.float32), np.asarray(d["faces"])
    t0 = time.perf_counter()
    rows = [r for r in method_pca(X, faces, (row["rel_rms"],), quick=True) if r["rel_rms"] <= row["rel_rms"]]
    del X
    row["clip_wire_bytes"] = wire_bytes(clip.read_bytes())
    row["pca_wire_bytes"] = min((r["wire_bytes"] for r in rows), default=None)
    ratio = None if not row["pca_wire_bytes"] else row["clip_wire_bytes"] / row["pca_wire_bytes"]
    row["clip_over_pca"] = ratio
    verdict = "not measured" if ratio is None else ("met" if ratio <= PCA_GOAL else "NOT met")
    figure = "-" if ratio is None else f"{ratio:.3f}"
    print(f"   {row['input']}: clip {row['clip_wire_bytes']:,} B on the wire at rel-RMS "
          f"{row['rel_rms']:.3g}, "
          f"quantised PCA {row['pca_wire_bytes'] or 0:,} B at <= that error "
          f"({time.perf_counter() - t0:.0f} s): {figure}x (goal <= {PCA_GOAL}x: {verdict})", flush=True)


def part_long(args: argparse.Namespace, work: Path) -> list[dict]:
    """(b) the long inputs, made (or read from the cache) first; with ``--pca`` each clip beside quantised
    PCA of the same frames at the same error."""
    for item in args.long_inputs:
        prepare(item, args.data)
    print(markdown_table([], header=True), flush=True)
    rows = []
    for item in args.long_inputs:
        for target in args.long_targets:
            row = fit_row(item.name, item.path, target, args.long_repeats, args.timeout, work)
            if args.pca:
                pca_peer(row, item.path, work / "fit.clip")
            rows.append(row)
    return rows


def part_service(args: argparse.Namespace) -> dict:
    """(c) the service input as a fit job with 1, then 2 job workers."""
    from benchmarks.fit_scale_service import service_runs

    item = args.service_input
    prepare(item, args.data)
    extra = dict(kv.split("=", 1) for kv in args.service_env)
    result = service_runs(item.path, item.name, args.long_targets[0], args.service_workers, extra,
                          args.timeout)
    print(service_table(result["rows"]), flush=True)
    return result


def git_commit() -> str:
    """The commit measured (with ``+dirty`` when the tree has changes)."""
    def git(*a: str) -> str:
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    return git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain") else "")


def main(argv: list[str] | None = None) -> int:
    """Run the chosen parts, print their tables and the goals, optionally write JSON."""
    args = parse_args(argv)
    t0 = time.perf_counter()
    out: dict = {"started": now(), "load_start": loads(), "commit": git_commit(), "cpus": os.cpu_count(),
                 "memory_gib": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1),
                 "quick": args.quick, "parts": {}}
    print(f"fit_scale: {out['started']}, commit {out['commit']}, {out['cpus']} CPUs, "
          f"{out['memory_gib']} GiB, load average {out['load_start']}", flush=True)
    rows: dict[str, list[dict]] = {}
    service: dict | None = None
    with tempfile.TemporaryDirectory(prefix="fit-scale-") as tmp:
        for part in args.parts:
            record: dict = {}
            with part_log(part, record):
                if part == "a":
                    rows["a"] = record["rows"] = part_sequences(args, Path(tmp))
                elif part == "b":
                    rows["b"] = record["rows"] = part_long(args, Path(tmp))
                else:
                    service = record["service"] = part_service(args)
            out["parts"][part] = record
    out.update(ended=now(), load_end=loads(), seconds=round(time.perf_counter() - t0, 1))
    out["goals"] = goal_lines(rows.get("a", []), rows.get("b", []), service)
    print(f"\n== summary: {out['started']} to {out['ended']} ({out['seconds'] / 60:.1f} min), load average "
          f"{out['load_start']} at the start, {out['load_end']} at the end, commit {out['commit']}")
    for part, record in out["parts"].items():
        print(f"\n({part}) {record['started']} to {record['ended']}, load average {record['load_start']} -> "
              f"{record['load_end']}")
        print(service_table(record["service"]["rows"]) if part == "c" else markdown_table(record["rows"]))
    print("\nGoals (issues 21 and 31):")
    for g in out["goals"]:
        print(f"- {g['goal']}: {g['measured']} -> {g['verdict']}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=str))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
