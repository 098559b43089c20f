"""The project in the compression benchmark: ``pdeanim fit POSES --target-rel-rms R`` with every other option
at the CLI's default, each fit in its own process (exit code, seconds, peak memory), bytes of the two parts
the HTTP API serves (topology, coefficients) as files and zstd -19 on the wire.

The fit's options come from one place, :data:`FIT_EXTRA_ARGS`. Any option there that differs from the CLI's
default must be named in :data:`FIT_LABELS` (option -> why), which the table's header prints; the benchmark
refuses to run otherwise (:func:`check_fit_options`, tested in tests/bench/).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from peers_common import CODE, code_label, log, result, wire_bytes

FIT_EXTRA_ARGS: tuple[str, ...] = ()
"""Options added to every ``pdeanim fit`` of the benchmark (none: the CLI's defaults)."""
FIT_LABELS: dict[str, str] = {}
"""Option dest -> why it differs from the CLI's default; printed in the table's header."""
FIXED_DESTS = {"command", "func", "poses", "out", "target_rel_rms"}
"""What every fit sets itself: the sub-command, input, output and the target being measured."""

CHILD = ("import re, resource, sys, time; from pdeanim_service.cli import main; t = time.perf_counter(); "
         "rc = main(sys.argv[1:]); s = time.perf_counter() - t; "
         "m = re.search(r'VmHWM:\\s*(\\d+)', open('/proc/self/status').read()); "
         "kb = int(m.group(1)) if m else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; "
         "print('BENCH', s, kb, file=sys.stderr); sys.exit(rc)")
"""Runs the ``pdeanim`` console script's main and prints its seconds and peak RSS (the process's own VmHWM:
``ru_maxrss`` of a forked + exec'd child also counts the parent's RSS at the fork)."""


def fit_argv(poses: str | Path, out: str | Path, target: float) -> list[str]:
    """The ``pdeanim`` arguments of one fit: the target and :data:`FIT_EXTRA_ARGS`, nothing else."""
    return ["fit", str(poses), "--out", str(out), "--target-rel-rms", repr(float(target)), *FIT_EXTRA_ARGS]


def nondefault_options(argv: list[str]) -> dict[str, object]:
    """Options of a ``pdeanim fit`` argv (as the CLI parses them) that differ from the CLI's defaults."""
    from pdeanim.cli import build_parser

    parser = build_parser()
    given = vars(parser.parse_args(argv))
    defaults = vars(parser.parse_args(["fit", "POSES", "--out", "OUT"]))
    return {k: v for k, v in given.items() if k not in FIXED_DESTS and defaults.get(k) != v}


def check_fit_options() -> dict[str, object]:
    """The benchmark's non-default fit options; raises ValueError for one not labelled in FIT_LABELS."""
    diff = nondefault_options(fit_argv("POSES", "OUT", 3e-3))
    unlabelled = sorted(set(diff) - set(FIT_LABELS))
    if unlabelled:
        raise ValueError(f"the benchmark's fit options differ from the CLI's defaults without a label in "
                         f"FIT_LABELS: {', '.join(f'{k}={diff[k]!r}' for k in unlabelled)}")
    return diff


def fit_label() -> str:
    """How the project is fitted, for the table's header (every non-default option named, with why)."""
    diff = check_fit_options()
    cmd = " ".join(["pdeanim", *fit_argv("POSES", "CLIP", 0.0)[:4], "--target-rel-rms R", *FIT_EXTRA_ARGS])
    if not diff:
        return f"`{cmd}` (every other option at the CLI's default)"
    notes = "; ".join(f"{k}={v!r} NOT the CLI default: {FIT_LABELS[k]}" for k, v in diff.items())
    return f"`{cmd}` ({notes})"


def fit_command(poses: str | Path, out: str | Path, target: float) -> list[str]:
    """The child process's command line: this interpreter running :data:`CHILD` with :func:`fit_argv`."""
    return [sys.executable, "-c", CHILD, *fit_argv(poses, out, target)]


def run_fit(poses: Path, out: Path, target: float, timeout: float) -> dict:
    """``pdeanim fit`` in a child process (the measured tree's pdeanim, peers_common.CODE, first on its path):
    exit code, seconds, peak RSS (MB), the stderr's verdict, the 1-min load average at its start and end."""
    cmd = fit_command(poses, out, target)
    load0 = os.getloadavg()[0]
    try:
        path = [str(CODE), *filter(None, [os.environ.get("PYTHONPATH")])]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(path)}
        p = subprocess.run(cmd, cwd=CODE, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"rc": None, "timeout": True}
    load = [load0, os.getloadavg()[0]]
    seconds = peak = None
    for line in p.stderr.splitlines():
        if line.startswith("BENCH "):
            _, s, kb = line.split()
            seconds, peak = float(s), int(kb) / 1024.0
    tail = [ln for ln in p.stderr.splitlines() if ln.startswith("pdeanim fit:") or "Error" in ln]
    return {"rc": p.returncode, "seconds": seconds, "peak_mb": peak, "message": " ".join(tail)[-400:],
            "load": load}


def load_fitted(out: Path):  # noqa: ANN201
    """(parts, clip) of a written CLIP file."""
    from pdeanim.clip import load_clip, read_clip_file

    parts = read_clip_file(out)
    return parts, load_clip(parts.topology, parts.coefficients)


def clip_row(parts, approx: np.ndarray, X: np.ndarray, target: float, res: dict) -> dict:  # noqa: ANN001
    """The result row of one fitted clip: both parts as files and on the wire."""
    wire = wire_bytes(parts.topology) + wire_bytes(parts.coefficients)
    r = result("clip", f"rel-RMS {target:g}", len(parts.topology) + len(parts.coefficients), approx, X,
               wire=wire, target=target, fit_s=res["seconds"], peak_mb=res["peak_mb"], exit_code=res["rc"],
               segments=parts.report.get("segments"), curves=parts.report.get("curves"),
               format_version=parts.report.get("format_version"), message=res.get("message", ""),
               bones=(parts.report.get("bones") or {}).get("n_bones", 0),
               residual_share=(parts.report.get("bones") or {}).get("residual_share"),
               coefficients_wire=wire_bytes(parts.coefficients), code=code_label(), fit_load=res.get("load"))
    r["target_met"] = bool(res["rc"] == 0 and r["rel_rms"] <= target * (1 + 1e-9))
    return r


def method_clip(name: str, poses: Path, X: np.ndarray, targets: tuple[float, ...], work: Path,
                timeout: float) -> list[dict]:
    """This project at each rel-RMS target, scored on every source frame."""
    rows = []
    for target in targets:
        out = work / f"{name}-{target:g}.clip"
        log(f"{name}: pdeanim fit --target-rel-rms {target:g}")
        res = run_fit(poses, out, target, timeout)
        if res.get("timeout") or not out.exists():
            log(f"{name}: fit at {target:g}: no clip ({res})")
            rows.append({"method": "clip", "setting": f"rel-RMS {target:g}", "target": target,
                         "failed": str(res)})
            continue
        parts, clip = load_fitted(out)
        rows.append(clip_row(parts, clip.evaluate(clip.frame_t()), X, target, res))
        r = rows[-1]
        log(f"{name}: clip at {target:g}: {r['file_bytes']} B file, {r['wire_bytes']} B wire, rel-RMS "
            f"{r['rel_rms']:.3g}, rel-max {r['rel_max']:.3g}, exit {res['rc']}, {res['seconds']:.1f} s")
        out.unlink()
    return rows
