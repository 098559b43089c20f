"""The compression benchmark's run of every sequence (issue 30): outputs of separate runs merged into one
table, issue 30's goals printed per cell with met / NOT met, gltfpack's settings narrowed on request, and the
clip measured from another tree (a ``git archive`` of another commit). Fast: no fit, tiny inputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
ROOT = BENCH.parent
sys.path.insert(0, str(BENCH))

import compression_peers  # noqa: E402
import peers_gltfpack  # noqa: E402
import peers_report  # noqa: E402
from peers_synthetic import rig4_tube  # noqa: E402

T = 3e-3


def peer(method: str, wire: int, rms: float, mx: float, **extra) -> dict:
    """A scored peer row (as results.json holds it)."""
    return {"method": method, "setting": extra.pop("setting", method), "file_bytes": wire, "wire_bytes": wire,
            "rel_rms": rms, "rel_max": mx, "kg": None, **extra}


def clip(wire: int, rms: float, mx: float, **extra) -> dict:
    """A clip row at target T."""
    return {**peer("clip", wire, rms, mx, setting=f"rel-RMS {T:g}"), "target": T, "target_met": rms <= T,
            "exit_code": 0, "fit_s": 100.0, "peak_mb": 300.0, **extra}


def test_goals_are_met_or_not_per_cell_at_both_yardsticks() -> None:
    rows = [clip(60_000, 0.9 * T, 2.5 * T, coefficients_wire=12_000),
            peer("pca", 110_000, 0.8 * T, 2.0 * T),  # meets RMS and max <= 3x: 60/110 = 0.55 -> met
            peer("dembones", 70_000, 0.95 * T, 9.0 * T, setting="64 bones (64 solved), rest 16-bit",
                 solve_s=80.0),  # RMS alone: 60/70 = 0.86 -> NOT met
            peer("gltfpack", 500_000, 0.5 * T, 1.0 * T),
            peer("skinned", 10_000, 0.1 * T, 0.2 * T)]
    g = peers_report.goal_cells(rows, T)
    assert g["strict"] == "0.55x PCA: met"
    assert g["rms"] == "0.86x Dem Bones: NOT met"
    assert g["max"] == "2.50x: met"
    assert g["band"] == "0.900: met"
    assert g["skinned"] == "1.20x: met"
    assert g["time"] == "100 s vs 80 s (64 bones (64 solved)): NOT met"
    table = peers_report.goals_table({"seq": rows}, (T, 1e-3))
    assert "| seq | 0.003 | 0.55x PCA: met | 0.86x Dem Bones: NOT met |" in table
    assert "| seq | 0.001 | no clip |" in table


def test_the_time_goal_prints_the_load_of_the_fit_and_of_the_solve_when_recorded() -> None:
    rows = [clip(60_000, 0.9 * T, 2.5 * T, fit_load=[12.4, 15.6]),
            peer("dembones", 70_000, 0.95 * T, 9.0 * T, setting="32 bones (32 solved), rest 16-bit",
                 solve_s=120.0, solve_load=[9.0, 11.2])]
    assert (peers_report.goal_cells(rows, T)["time"]
            == "100 s (load 12-16) vs 120 s (32 bones (32 solved); load 9-11): met")


def test_a_clip_below_the_band_or_past_3x_max_is_not_met_and_no_peer_is_said() -> None:
    g = peers_report.goal_cells([clip(60_000, 0.5 * T, 3.5 * T)], T)
    assert g["band"] == "0.500: NOT met"
    assert g["max"] == "3.50x: NOT met"
    assert g["strict"] == g["rms"] == "no peer meets it"


def write_run(folder: Path, results: dict, loads: list[float]) -> None:
    folder.mkdir(parents=True)
    (folder / "results.json").write_text(json.dumps(results))
    (folder / "run.json").write_text(json.dumps({
        "seconds": 10.0, "loads": loads, "finished": "2026-12-07 18:00 UTC",
        "runs": [{"command": "compression_peers.py --methods x", "started": "2026-12-07 17:59 UTC",
                  "finished": "2026-12-07 18:00 UTC", "seconds": 10.0, "project": "pdeanim fit",
                  "versions": "commit abc"}]}))


def test_merge_joins_the_rows_of_separate_runs_and_keeps_the_first_clip(tmp_path: Path, capsys) -> None:
    inp = {"method": "input", "setting": "4 frames x 3 vertices", "frames": 4, "vertices": 3, "faces": 1}
    write_run(tmp_path / "peers", {"seq": [inp, peer("pca", 110_000, 0.8 * T, 2.0 * T)]}, [3.0, 5.0])
    write_run(tmp_path / "bones", {"seq": [inp, peer("dembones", 70_000, 0.95 * T, 9.0 * T, solve_s=80.0)],
                                   "other": [inp]}, [7.0])
    for folder, wire, code in (("clip-a", 60_000, "commit aaa1234"), ("clip-b", 50_000, "commit bbb1234")):
        write_run(tmp_path / folder, {"seq": [inp, clip(wire, 0.9 * T, 2.5 * T, code=code)]}, [4.0])
    out = tmp_path / "merged"
    folders = ",".join(str(tmp_path / d) for d in ("peers", "bones", "clip-a", "clip-b"))
    assert compression_peers.main(["--merge", folders, "--out", str(out), "--targets", "0.003",
                                   "--sequences", "seq,other"]) == 0
    merged = json.loads((out / "results.json").read_text())
    assert list(merged) == ["seq", "other"]
    assert [r["method"] for r in merged["seq"]] == ["input", "pca", "dembones", "clip"]
    assert next(r for r in merged["seq"] if r["method"] == "clip")["code"] == "commit aaa1234"
    table = (out / "table.md").read_text()
    assert table == capsys.readouterr().out
    assert "4 output folders merged" in table and "1-min load average 3.0..7.0" in table
    assert "`compression_peers.py --methods x`" in table
    assert "| seq | 0.003 | 0.55x PCA: met | 0.86x Dem Bones: NOT met |" in table
    assert "| seq | 0.003 | 60,000 (0; 0.90, 2.5x; aaa1234) | PCA 110,000" in table


def test_gltfpack_settings_can_be_narrowed(tmp_path: Path) -> None:
    args = compression_peers.parse_args(["--gltfpack-vp", "8,10", "--gltfpack-no-vpf", "--methods",
                                         "gltfpack"])
    assert args.gltfpack_vp == (8, 10) and args.gltfpack_no_vpf
    X, faces = rig4_tube(frames=6)
    rows = peers_gltfpack.method_gltfpack(X, faces, tmp_path, 120.0, False, (9,), floats=False)
    assert sorted(r["setting"] for r in rows) == ["-cc -vp 9", "-cc -vp 9 -ce khr"]


def test_the_measured_code_can_be_another_tree(tmp_path: Path) -> None:
    tree = tmp_path / "other"
    tree.mkdir()
    (tree / "pdeanim").symlink_to(ROOT / "pdeanim")
    probe = ("import sys; sys.path.insert(0, sys.argv[1]); import peers_common, peers_clip, pdeanim; "
             "print(pdeanim.__file__); print(peers_common.code_label()); print(peers_clip.CODE)")
    env = {**os.environ, "PDEANIM_CODE": str(tree), "PDEANIM_CODE_LABEL": "git archive abc1234"}
    env.pop("PYTHONPATH", None)
    p = subprocess.run([sys.executable, "-c", probe, str(BENCH)], env=env, capture_output=True, text=True,
                       cwd=tmp_path, check=True)
    file, label, code = p.stdout.splitlines()
    assert file == str(tree / "pdeanim" / "__init__.py")
    assert label == "git archive abc1234"
    assert code == str(tree.resolve())
