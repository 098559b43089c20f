"""The paper's Table 2/3 comparison on AnimatedMorphSphere: an open and a closed curve (~65 points) at two
frames (20 and 100), dynamic PDE (one 8-coefficient fit over both frames) vs cubic Bezier and uniform cubic
B-spline (4 control points per frame, fitted frame by frame) on the same chord-length u.

Prints what each method stores (vector-valued design variables and the float values in all), E_A1, E_m1, E_A2,
E_m2 (Eq. 23-24, x 1e-3 as in the paper), RMS relative to the bbox diagonal, and CPU ms (median of repeated
fits; shared, loaded 2-core machine). The PDE stores 8 vector knots plus m and D per coordinate; fitting the
displacement from the first frame also stores that frame's curve (N points), which is counted.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from pdeanim.curveset import CurveSet
from pdeanim.model.baselines import fit_bezier, fit_bspline
from pdeanim.model.fitcore import (
    items_from_curves,
    items_to_vertices,
    reconstruct_items,
    space_stage,
    time_stage,
)
from pdeanim.model.metrics import bbox_diagonal, paper_errors
from pdeanim.model.parameterisation import chord_parameters
from pdeanim.model.segments import Segmentation
from pdeanim.posefiles import load_poses

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "AnimatedMorphSphere.npz"


def band_curves(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(open, closed) vertex index curves of ~64 distinct points from the two fullest adjacent rings.

    This sphere has 32 distinct points per ring, so one ring is too short for the paper's ~70-point curves:
    the open curve runs once round one ring and continues round the next; the closed curve runs round one
    ring and back round the other (the outline of a thin band), ending where it started.
    """
    _, first = np.unique(np.round(rest, 5), axis=0, return_index=True)
    first = np.sort(first)
    p = rest[first]
    axis = int(np.argmax(np.ptp(p, axis=0)))
    others = [i for i in range(3) if i != axis]
    levels = np.round(p[:, axis], 3)
    vals, counts = np.unique(levels, return_counts=True)
    full = vals[counts == counts.max()]
    mid = int(np.argmin(np.abs(full)))
    a_level, b_level = full[mid], full[mid + 1] if mid + 1 < len(full) else full[mid - 1]

    def ring(level: float) -> np.ndarray:
        idx = first[levels == level]
        return idx[np.argsort(np.arctan2(rest[idx, others[1]], rest[idx, others[0]]))]

    ra, rb = ring(a_level), ring(b_level)
    return np.concatenate([ra, rb]), np.concatenate([ra, rb[::-1], ra[:1]])


def pde_fit(frames: np.ndarray, curve: np.ndarray, absolute: bool = True) -> np.ndarray:
    """Dynamic-PDE fit of one curve over two frames (t = 0, 1); returns fitted points (2, N, 3)."""
    cs = CurveSet.from_lists([list(range(len(curve)))])
    idx, mask = cs.padded()
    X = frames[:, curve].astype(np.float64)
    base = 0.0 if absolute else X[:1]
    Y = items_from_curves(X - base, idx, mask)
    u = chord_parameters(X[0][idx], mask)
    sp = space_stage(Y, np.repeat(u, 3, axis=0), np.repeat(mask, 3, axis=0))
    ts = time_stage(sp, Segmentation(np.array([0, 1]), np.array([0.0, 1.0])))
    return items_to_vertices(reconstruct_items(sp, ts), idx, mask, len(curve)) + base


def timed(fn, repeats: int = 30) -> tuple[np.ndarray, float]:
    out = fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return out, float(np.median(samples) * 1e3)


def row(name: str, design: int, stored: int, orig: np.ndarray, fitted: np.ndarray, ms: float,
        diag: float) -> str:
    """One table row; ``design`` vector design variables, ``stored`` float values kept in all."""
    Ea, Em = paper_errors(orig, fitted)
    rms = np.sqrt(np.mean(np.sum((orig - fitted) ** 2, axis=-1))) / diag
    return (f"{name:22s} {design:4d} {stored:6d} {Ea[0] * 1e3:9.3f} {Em[0] * 1e3:9.3f} "
            f"{Ea[1] * 1e3:9.3f} {Em[1] * 1e3:9.3f} "
            f"{rms:10.2e} {ms:8.3f}")


def main() -> None:
    poses = load_poses(DATA)
    frames = poses.vertices[[20, 100]].astype(np.float64)
    diag = bbox_diagonal(poses.vertices[0])
    open_, closed = band_curves(poses.vertices[20].astype(np.float64))
    for label, curve in (("open curve (OC)", open_), ("closed curve (CC)", closed)):
        orig = frames[:, curve]
        u = chord_parameters(orig[0][None], np.ones((1, len(curve)), bool))
        print(f"\n{label}: {len(curve)} points per frame, frames 20 and 100 (PM = {2 * len(curve)})")
        print(f"{'method':22s} {'PBB':>4s} {'floats':>6s} {'E_A1e-3':>9s} {'E_m1e-3':>9s} "
              f"{'E_A2e-3':>9s} {'E_m2e-3':>9s} "
              f"{'rel rms':>10s} {'CPU ms':>8s}")
        pts = orig[:, None]
        n = len(curve)
        pde_floats = 8 * 3 + 2 * 3  # 8 vector knots, m and D per coordinate
        for name, fn, design, stored in (
                ("PDE (absolute)", lambda c=curve: pde_fit(frames, c, True), 8, pde_floats),
                ("PDE (displacement)", lambda c=curve: pde_fit(frames, c, False), 8 + n, pde_floats + 3 * n)):
            fitted, ms = timed(fn)
            print(row(name, design, stored, orig, fitted, ms, diag))
        (_, fb), ms = timed(lambda p=pts, uu=u: fit_bezier(p, uu))
        print(row("cubic Bezier", 8, 24, orig, fb[:, 0], ms, diag))
        (_, fs), ms = timed(lambda p=pts, uu=u: fit_bspline(p, uu, n_ctrl=4))
        print(row("uniform cubic B-spline", 8, 24, orig, fs[:, 0], ms, diag))
    print("\nPBB: vector-valued design variables stored (PDE: 8 knots for both frames, plus the first "
          "frame's N points when fitting the displacement; Bezier/B-spline: 4 control points per frame). "
          "floats: every stored value, m and D per coordinate included.")
    print(f"load average {os.getloadavg()[0]:.1f} (shared 2-core machine)")


if __name__ == "__main__":
    main()
