"""Tables and goal verdicts of the fit-scale benchmark (``fit_scale.py``): pure functions of its rows."""

from __future__ import annotations

GOAL_FV_PER_S = 150_000
GOAL_SPREAD = 2.0
GOAL_SECONDS = 300.0
GOAL_SECONDS_31 = 150.0
"""Issue 31: the 1,000 x ~34k CLI fit in at most this many seconds (and under GOAL_PEAK_BYTES)."""
GOAL_PEAK_BYTES = 2e9
GOAL_WORKERS_RATIO = 0.6
GOAL_TARGET = 3e-3

FIT_COLUMNS = ("| input | frames | vertices | frame-vertices | target rel-RMS | wall s | fit s "
               "| frame-vertices/s | peak MiB | met | rel-RMS | rel-max | bytes | windowed | segments | runs "
               "| load |")
SERVICE_COLUMNS = ("| input | job workers | upload s | job wall s (submit to done) | job run s "
                   "| frame-vertices/s | job peak MiB (sampled) | met | rel-RMS | rel-max | bytes | load |")


def _num(v: float | None, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _yes(v: bool | None) -> str:
    return "-" if v is None else "yes" if v else "no"


def rate(fv_per_s: float | None) -> str:
    """Frame-vertices per second in thousands: ``152k``."""
    return "-" if fv_per_s is None else f"{fv_per_s / 1000:.0f}k"


def fit_line(r: dict) -> str:
    """One markdown row of a CLI fit."""
    wall = f"{r['wall_s']:.1f}" + (" (timed out)" if r.get("timed_out") else "")
    return (f"| {r['input']} | {r['frames']} | {r['vertices']:,} | {r['frame_vertices'] / 1e6:.2f} M "
            f"| {r['target']:g} | {wall} | {_num(r.get('fit_s'), '.1f')} | {rate(r['fv_per_s'])} "
            f"| {r['peak_mib']:.0f} | {_yes(r.get('met'))} | {_num(r.get('rel_rms'), '.2e')} "
            f"| {_num(r.get('rel_max'), '.2e')} | {_num(r.get('bytes'), ',')} | {_yes(r.get('windowed'))} "
            f"| {_num(r.get('segments'), 'd')} | {r['runs']} | {r['load']:.1f} |")


def markdown_table(rows: list[dict], header: bool = True) -> str:
    """The markdown table of CLI fit rows (only the header when ``rows`` is empty; no header if not asked)."""
    lines = [FIT_COLUMNS, "|---" * FIT_COLUMNS.count(" | ") + "|---|"] if header else []
    return "\n".join(lines + [fit_line(r) for r in rows])


def service_table(rows: list[dict]) -> str:
    """The markdown table of the service runs."""
    lines = [SERVICE_COLUMNS, "|---" * SERVICE_COLUMNS.count(" | ") + "|---|"]
    for r in rows:
        state = "" if r.get("state") == "succeeded" else f" ({r.get('state')})"
        lines.append(
            f"| {r['input']} | {r['workers']} | {_num(r.get('upload_s'), '.1f')} "
            f"| {_num(r.get('job_wall_s'), '.1f')}{state} | {_num(r.get('job_run_s'), '.1f')} "
            f"| {rate(r.get('fv_per_s'))} | {_num(r.get('peak_mib'), '.0f')} "
            f"| {_yes(r.get('met'))} | {_num(r.get('rel_rms'), '.2e')} | {_num(r.get('rel_max'), '.2e')} "
            f"| {_num(r.get('bytes'), ',')} | {r['load']:.1f} |")
    return "\n".join(lines)


def _verdict(ok: bool | None) -> str:
    return "not measured in this run" if ok is None else "met" if ok else "NOT met"


def _at_goal_target(rows: list[dict]) -> list[dict]:
    return [r for r in rows if abs(r["target"] - GOAL_TARGET) < 1e-12]


def speed_goals(a: list[dict], b: list[dict]) -> list[dict]:
    """The frame-vertices-per-second goals at 3e-3: every input at least 150k, and the slowest at most 2x
    slower per frame-vertex than the fastest."""
    out = []
    for label, rows in (("the sequences (a)", _at_goal_target(a)),
                        ("the long inputs (b)", _at_goal_target(b))):
        slow = min(rows, key=lambda r: r["fv_per_s"], default=None)
        out.append({"goal": f">= {GOAL_FV_PER_S // 1000}k frame-vertices/s at rel-RMS 3e-3 on every one of "
                            f"{label}",
                    "measured": "-" if slow is None else
                    f"slowest {rate(slow['fv_per_s'])} ({slow['input']})",
                    "verdict": _verdict(None if slow is None else slow["fv_per_s"] >= GOAL_FV_PER_S)})
    rows = _at_goal_target(a) + _at_goal_target(b)
    measured, ok = "-", None
    if rows:
        slow, fast = min(rows, key=lambda r: r["fv_per_s"]), max(rows, key=lambda r: r["fv_per_s"])
        spread = fast["fv_per_s"] / slow["fv_per_s"]
        measured = (f"{spread:.1f}x ({slow['input']} {rate(slow['fv_per_s'])} against {fast['input']} "
                    f"{rate(fast['fv_per_s'])})")
        ok = spread <= GOAL_SPREAD
    out.append({"goal": f"no input (a and b) slower per frame-vertex than {GOAL_SPREAD:g}x the fastest, "
                        "at 3e-3",
                "measured": measured, "verdict": _verdict(ok)})
    return out


def is_goal_size(r: dict) -> bool:
    """Whether a row is the goal's 1,000-frame x ~34k-vertex input."""
    return r["frames"] >= 1000 and 30_000 <= r["vertices"] <= 40_000


def long_fit_goals(b: list[dict], service: dict | None) -> list[dict]:
    """The 1,000 x ~34k goal through the CLI and a service job, and 2 workers against 1."""
    cli = next((r for r in _at_goal_target(b) if is_goal_size(r)), None)
    out = [{"goal": "1,000 frames x ~34k vertices at 3e-3 through the CLI: < 5 min, peak < 2 GB, target met",
            "measured": "-" if cli is None else (f"{cli['wall_s']:.0f} s, {cli['peak_mib']:.0f} MiB, target "
                                                  f"{'met' if cli['met'] else 'not met'} ({cli['input']})"),
            "verdict": _verdict(None if cli is None else cli["wall_s"] < GOAL_SECONDS
                                and cli["peak_mib"] * 2**20 < GOAL_PEAK_BYTES and cli["met"])}]
    out.append({"goal": "issue 31: the same CLI fit in <= 150 s and < 2 GB peak",
                "measured": "-" if cli is None else f"{cli['wall_s']:.0f} s, {cli['peak_mib']:.0f} MiB "
                                                    f"(load {cli['load']:.1f})",
                "verdict": _verdict(None if cli is None else cli["wall_s"] <= GOAL_SECONDS_31
                                    and cli["peak_mib"] * 2**20 < GOAL_PEAK_BYTES)})
    rows = (service or {}).get("rows", [])
    one = next((r for r in rows if r["workers"] == 1 and is_goal_size(r)), None)
    ok = None
    if one is not None:
        ok = (one["state"] == "succeeded" and one["job_wall_s"] < GOAL_SECONDS and bool(one["met"])
              and (one["peak_mib"] is None or one["peak_mib"] * 2**20 < GOAL_PEAK_BYTES))
    out.append({"goal": "the same through a service job (1 worker): < 5 min, peak < 2 GB, target met",
                "measured": "-" if one is None else (
                    f"{one['state']}, {_num(one.get('job_wall_s'), '.0f')} s, "
                    f"{_num(one.get('peak_mib'), '.0f')} MiB sampled, target "
                    f"{'met' if one.get('met') else 'not met'}"),
                "verdict": _verdict(ok)})
    by = {r["workers"]: r for r in rows if r["state"] == "succeeded"}
    ratio = by[2]["job_wall_s"] / by[1]["job_wall_s"] if 1 in by and 2 in by else None
    name = rows[0]["input"] if rows else "-"
    out.append({"goal": f"2 job workers <= {GOAL_WORKERS_RATIO}x the wall time of 1",
                "measured": "-" if ratio is None else (f"{ratio:.2f}x ({by[2]['job_wall_s']:.0f} s against "
                                                        f"{by[1]['job_wall_s']:.0f} s, {name})"),
                "verdict": _verdict(None if ratio is None else ratio <= GOAL_WORKERS_RATIO)})
    return out


def goal_lines(a: list[dict], b: list[dict], service: dict | None) -> list[dict]:
    """Every goal of issue 21 that this benchmark measures: goal, measured figure, verdict."""
    return speed_goals(a, b) + long_fit_goals(b, service)
