"""Tables (markdown, to paste into docs/compression.md) and plots of the compression benchmark's results."""

from __future__ import annotations

import re
from pathlib import Path

PEERS = ("gltfpack", "pca", "dembones")
"""The strongest peers: the wire ratio's yardstick is the smallest of them that meets the target."""
REFERENCES = ("keyframes",)
LABELS = {"gltfpack": "gltfpack", "pca": "PCA", "dembones": "Dem Bones", "keyframes": "keyframes"}


def nbytes(n: int | None) -> str:
    """Exact bytes with thousands separators."""
    return "-" if n is None else f"{n:,}"


MAX_YARDSTICK = 3.0
"""The stricter yardstick: a peer must also keep its rel-max within this multiple of the target (as the clip
does)."""


def best(rows: list[dict], method: str, target: float, key: str = "wire_bytes",
         max_ratio: float | None = None) -> dict | None:
    """The smallest (by ``key``) row of ``method`` that meets rel-RMS <= target (and rel-max <= max_ratio x
    target when given)."""
    ok = [r for r in rows if r.get("method") == method and r.get("rel_rms") is not None
          and r["rel_rms"] <= target * (1 + 1e-9)
          and (max_ratio is None or r["rel_max"] <= max_ratio * target * (1 + 1e-9))]
    return min(ok, key=lambda r: r[key]) if ok else None


def clip_at(rows: list[dict], target: float) -> dict | None:
    """The project's row fitted for ``target``."""
    return next((r for r in rows if r.get("method") == "clip" and r.get("target") == target), None)


def peer_cell(r: dict | None, target: float, ran: bool = True) -> str:
    """file / wire (setting; rel-RMS, rel-max as a multiple of the target) of a peer's best row."""
    if r is None:
        return "- (none meets it)" if ran else "not run (--methods)"
    return (f"{nbytes(r['file_bytes'])} / {nbytes(r['wire_bytes'])} ({r['setting']}; RMS "
            f"{r['rel_rms']:.2g}, max {r['rel_max'] / target:.2g}x)")


def ratios(rows: list[dict], target: float, max_ratio: float | None = None) -> tuple[str, str, str]:
    """(smallest peer on the wire, wire ratio, file ratio) of the clip at ``target`` (peers also within
    ``max_ratio`` x target at their max error when given)."""
    c = clip_at(rows, target)
    wire = [r for m in PEERS if (r := best(rows, m, target, max_ratio=max_ratio))]
    file = [r for m in PEERS if (r := best(rows, m, target, "file_bytes", max_ratio))]
    if not wire:
        return "-", "-", "-"
    w = min(wire, key=lambda r: r["wire_bytes"])
    f = min(file, key=lambda r: r["file_bytes"])
    name = f"{LABELS[w['method']]} {nbytes(w['wire_bytes'])}"
    if c is None or "wire_bytes" not in c:
        return name, "no clip", "no clip"
    miss = "" if c["target_met"] else " (target missed)"
    return (name, f"{c['wire_bytes'] / w['wire_bytes']:.2f}{miss}",
            f"{c['file_bytes'] / f['file_bytes']:.2f}{miss}")


def summary_table(results: dict[str, list[dict]], targets: tuple[float, ...]) -> str:
    """Per sequence and target: the clip and the smallest file of each peer meeting the target."""
    head = ["sequence", "target", "clip met", "clip rel-RMS", "clip rel-max (x target)", "clip file / wire",
            *[f"{LABELS[m]} file / wire" for m in (*PEERS, *REFERENCES)],
            f"smallest peer, RMS + max <= {MAX_YARDSTICK:g}x (wire)", "wire ratio", "file ratio",
            "smallest peer, RMS alone (wire)", "wire ratio", "file ratio"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        for t in targets:
            c = clip_at(rows, t)
            if c is None or "wire_bytes" not in c:
                clip = ["no clip", "-", "-", "-"]
            else:
                clip = ["yes" if c["target_met"] else f"NO (exit {c['exit_code']})", f"{c['rel_rms']:.3g}",
                        f"{c['rel_max']:.3g} ({c['rel_max'] / t:.1f}x)",
                        f"{nbytes(c['file_bytes'])} / {nbytes(c['wire_bytes'])}"]
            peers = [peer_cell(best(rows, m, t), t, any(r.get("method") == m for r in rows))
                     for m in (*PEERS, *REFERENCES)]
            lines.append("| " + " | ".join([name, f"{t:g}", *clip, *peers, *ratios(rows, t, MAX_YARDSTICK),
                                            *ratios(rows, t)]) + " |")
    return "\n".join(lines)


GOAL_STRICT = 0.6
"""Issue 30: clip wire bytes at most this multiple of the strongest peer meeting rel-RMS and rel-max <= 3x."""
GOAL_RMS = 0.8
"""Issue 30: clip wire bytes at most this multiple of the strongest peer meeting the rel-RMS alone."""
GOAL_RMS_BAND = (0.85, 1.0)
"""Issue 30: the clip's rel-RMS as a share of the target."""
GOAL_SKINNED = 1.2
"""Issue 30: a skinned input's clip coefficients at most this multiple of its own gltfpack'd animation."""


def _verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def smallest_peer(rows: list[dict], target: float, max_ratio: float | None = None) -> dict | None:
    """The smallest row on the wire of any peer (gltfpack, PCA, Dem Bones) meeting the target."""
    found = [r for m in PEERS if (r := best(rows, m, target, max_ratio=max_ratio))]
    return min(found, key=lambda r: r["wire_bytes"]) if found else None


def goal_cells(rows: list[dict], target: float) -> dict[str, str]:
    """Each goal of issue 30 at one sequence and target: the figure and met / NOT met."""
    c = clip_at(rows, target)
    if c is None or "wire_bytes" not in c:
        return {}
    out = {}
    for key, cap, mr in (("strict", GOAL_STRICT, MAX_YARDSTICK), ("rms", GOAL_RMS, None)):
        p = smallest_peer(rows, target, mr)
        if p is None:
            out[key] = "no peer meets it"
        else:
            ratio = c["wire_bytes"] / p["wire_bytes"]
            out[key] = f"{ratio:.2f}x {LABELS[p['method']]}: {_verdict(c['target_met'] and ratio <= cap)}"
    within = c["rel_max"] <= MAX_YARDSTICK * target * (1 + 1e-9)
    out["max"] = f"{c['rel_max'] / target:.2f}x: {_verdict(within)}"
    share = c["rel_rms"] / target
    lo, hi = GOAL_RMS_BAND
    out["band"] = f"{share:.3f}: {_verdict(lo <= share <= hi * (1 + 1e-9))}"
    sk = best(rows, "skinned", target)
    if sk is not None and c.get("coefficients_wire"):
        ratio = c["coefficients_wire"] / sk["wire_bytes"]
        out["skinned"] = f"{ratio:.2f}x: {_verdict(ratio <= GOAL_SKINNED)}"
    solves = [r["solve_s"] for r in rows if r.get("method") == "dembones" and r.get("solve_s") is not None]
    db = best(rows, "dembones", target)  # the strongest Dem Bones setting's solve, else the fastest
    solve = db["solve_s"] if db is not None else (min(solves) if solves else None)
    if solve is not None and c.get("fit_s") is not None:
        which = db["setting"].split(",")[0] if db is not None else "fastest solve"
        src = db if db is not None else min((r for r in rows if r.get("method") == "dembones"
                                             and r.get("solve_s") is not None), key=lambda r: r["solve_s"])
        out["time"] = (f"{c['fit_s']:.0f} s{_load(c.get('fit_load'))} vs {solve:.0f} s ({which}"
                       f"{_load(src.get('solve_load'), ';')}): {_verdict(c['fit_s'] <= solve)}")
    return out


def _load(load: list[float] | None, sep: str = "") -> str:
    """' (load A-B)': the 1-min load average at a timed step's start and end, when recorded."""
    if not load:
        return ""
    return f"{sep} load {load[0]:.0f}-{load[1]:.0f}" if sep else f" (load {load[0]:.0f}-{load[1]:.0f})"


def _peer_brief(r: dict, target: float) -> str:
    setting = r["setting"].split(",")[0] if r["method"] == "dembones" else r["setting"]
    return (f"{LABELS[r['method']]} {nbytes(r['wire_bytes'])} ({setting}; RMS {r['rel_rms'] / target:.2f}, "
            f"max {r['rel_max'] / target:.1f}x)")


def compact_table(results: dict[str, list[dict]], targets: tuple[float, ...]) -> str:
    """One line per sequence and target: the clip on the wire (bones; rel-RMS as a share of the target,
    rel-max as a multiple; the measured commit) and the smallest peer at each yardstick with the clip's wire
    ratio to it."""
    head = ["input", "target", "clip wire (bones; rel-RMS share, rel-max x)",
            f"smallest peer, RMS + max <= {MAX_YARDSTICK:g}x", "ratio", "smallest peer, RMS alone", "ratio"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        for t in targets:
            c = clip_at(rows, t)
            ok = c is not None and "wire_bytes" in c
            if not ok:
                cell = "not run" if c is None else "fit failed"
            else:
                miss = "" if c["target_met"] else ", target missed"
                code = re.search(r"\b[0-9a-f]{7,}\b", c.get("code") or "")
                cell = (f"{nbytes(c['wire_bytes'])} ({c.get('bones', 0)}; {c['rel_rms'] / t:.2f}, "
                        f"{c['rel_max'] / t:.1f}x{miss}{'; ' + code.group(0) if code else ''})")
            cells = [name, f"{t:g}", cell]
            for mr in (MAX_YARDSTICK, None):
                p = smallest_peer(rows, t, mr)
                if p is None:
                    cells += ["none meets it", "-"]
                else:
                    cells += [_peer_brief(p, t), f"{c['wire_bytes'] / p['wire_bytes']:.2f}" if ok else "-"]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def goals_table(results: dict[str, list[dict]], targets: tuple[float, ...]) -> str:
    """Issue 30's goals per sequence and target, each figure beside met / NOT met."""
    head = ["sequence", "target", f"<= {GOAL_STRICT:g}x peer (RMS + max <= {MAX_YARDSTICK:g}x)",
            f"<= {GOAL_RMS:g}x peer (RMS alone)", f"rel-max <= {MAX_YARDSTICK:g}x",
            f"rel-RMS {GOAL_RMS_BAND[0]:g}-{GOAL_RMS_BAND[1]:g} of target",
            f"skinned <= {GOAL_SKINNED:g}x", "fit time <= Dem Bones solve"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        for t in targets:
            g = goal_cells(rows, t)
            if not g:
                lines.append(f"| {name} | {t:g} | no clip |" + " - |" * (len(head) - 3))
                continue
            cells = [g.get(k, "-") for k in ("strict", "rms", "max", "band", "skinned", "time")]
            lines.append("| " + " | ".join([name, f"{t:g}", *cells]) + " |")
    return "\n".join(lines)


def clip_table(results: dict[str, list[dict]]) -> str:
    """Every fit of the project: exit code, errors against the target, bytes, segments, time, memory."""
    head = ["sequence", "target", "exit", "rel-RMS (x target)", "rel-max (x target)", "file", "wire",
            "format", "bones", "residual share", "segments", "curves", "fit s", "peak MB"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        for r in rows:
            if r.get("method") != "clip":
                continue
            t = r["target"]
            if "wire_bytes" not in r:
                lines.append(f"| {name} | {t:g} | failed: {r.get('failed', '')[:80]} |" + " |" * 11)
                continue
            lines.append(f"| {name} | {t:g} | {r['exit_code']} | {r['rel_rms']:.3g} ({r['rel_rms'] / t:.2f}) "
                         f"| {r['rel_max']:.3g} ({r['rel_max'] / t:.1f}) | {nbytes(r['file_bytes'])} | "
                         f"{nbytes(r['wire_bytes'])} | {r.get('format_version')} | {r.get('bones', 0)} | "
                         f"{_share(r.get('residual_share'))} | {r.get('segments')} | "
                         f"{r.get('curves')} | {r['fit_s']:.1f} | {r['peak_mb']:.0f} |")
    return "\n".join(lines)


def skinned_table(results: dict[str, list[dict]], targets: tuple[float, ...]) -> str:
    """Per skinned input and target: the clip's coefficients on the wire against the smallest gltfpack'd
    skinned animation (animation + skin data) that meets the target."""
    head = ["input", "target", "clip bones", "clip coefficients wire", "clip rel-RMS / rel-max",
            "skinned gltfpack wire (setting; rel-RMS, rel-max)", "ratio"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        if not any(r.get("method") == "skinned" for r in rows):
            continue
        for t in targets:
            c, p = clip_at(rows, t), best(rows, "skinned", t)
            if c is None or "wire_bytes" not in c or p is None:
                lines.append(f"| {name} | {t:g} | - | - | - | {peer_cell(p, t)} | - |")
                continue
            lines.append(f"| {name} | {t:g} | {c.get('bones', 0)} | {nbytes(c.get('coefficients_wire'))} | "
                         f"{c['rel_rms']:.3g} / {c['rel_max']:.3g} | {nbytes(p['wire_bytes'])} "
                         f"({p['setting']}; {p['rel_rms']:.2g}, {p['rel_max']:.2g}) | "
                         f"{c['coefficients_wire'] / p['wire_bytes']:.2f} |")
    return "\n".join(lines)


def _share(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def heldout_table(results: dict[str, list[dict]]) -> str:
    """Held-out frames: the stated protocol per target, the earlier one as the last column."""
    head = ["sequence", "target", "kept / in between / after", "fit exit (rel-RMS on kept)",
            "clip rel-RMS / rel-max", "linear", "Catmull-Rom", "clip / linear", "clip / Catmull-Rom",
            "earlier protocol: clip / Catmull-Rom (fit target)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rows in results.items():
        h = [r for r in rows if r.get("method") == "heldout"]
        early = next((r for r in h if r["protocol"] == "earlier" and "clip_rel_rms" in r), None)
        early_cell = "-" if early is None else f"{early['clip_over_catmull_rom']:.3f} ({early['target']:.2g})"
        for r in (r for r in h if r["protocol"] == "stated"):
            if "clip_rel_rms" not in r:
                lines.append(f"| {name} | {r['target']:g} | failed: {r.get('failed', '')[:80]} |" + " |" * 7)
                continue
            kept = r.get("kept_rel_rms")
            lines.append(
                f"| {name} | {r['target']:g} | {r['kept']} / {r['measured']} / {r.get('trailing', 0)} | "
                f"{r['fit_exit']} ({'-' if kept is None else f'{kept:.3g}'}) | "
                f"{r['clip_rel_rms']:.3g} / {r['clip_rel_max']:.3g} | "
                f"{r['linear_rel_rms']:.3g} / {r['linear_rel_max']:.3g} | "
                f"{r['catmull_rom_rel_rms']:.3g} / {r['catmull_rom_rel_max']:.3g} | "
                f"{r['clip_over_linear']:.3f} | {r['clip_over_catmull_rom']:.3f} | {early_cell} |")
    return "\n".join(lines)


def rows_table(name: str, rows: list[dict]) -> str:
    """Every scored row of one sequence."""
    lines = [f"#### {name}", "", "| method | setting | file | wire | rel-RMS | rel-max | KG % | notes |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "wire_bytes" not in r:
            continue
        notes = [f"{k} {r[k]:.1f}" for k in ("fit_s", "solve_s", "pack_s") if r.get(k) is not None]
        notes += [f"{k} {r[k]}" for k in ("exit_code", "decoded_vertices") if r.get(k) is not None]
        kg = "-" if r.get("kg") is None else f"{r['kg']:.3g}"
        lines.append(f"| {r['method']} | {r['setting']} | {nbytes(r['file_bytes'])} | "
                     f"{nbytes(r['wire_bytes'])} | {r['rel_rms']:.3g} | {r['rel_max']:.3g} | {kg} | "
                     f"{', '.join(notes)} |")
    return "\n".join(lines)


def pareto_plot(name: str, rows: list[dict], targets: tuple[float, ...], path: Path) -> None:
    """Wire bytes vs rel-RMS, log-log: every scored setting of each method, its lower envelope as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for m in ("clip", *PEERS, *REFERENCES):
        pts = sorted((r["wire_bytes"], r["rel_rms"]) for r in rows
                     if r.get("method") == m and r.get("wire_bytes") and r.get("rel_rms"))
        if not pts:
            continue
        front, low = [], float("inf")
        for b, e in pts:
            if e < low:
                front.append((b, e))
                low = e
        line = ax.plot(*zip(*front, strict=True), lw=1.2, label=LABELS.get(m, "clip (pdeanim fit)"))[0]
        ax.scatter(*zip(*pts, strict=True), s=10, color=line.get_color())
    for t in targets:
        ax.axhline(t, color="grey", lw=0.5, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("bytes on the wire (zstd -19 of each file)")
    ax.set_ylabel("rel-RMS (to frame 0's bbox diagonal)")
    ax.set_title(f"{name}: wire bytes vs error")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
