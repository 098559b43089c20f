"""Geometric quality of a curve set: turning angles and step lengths, the smoothness the space basis needs."""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet


def curve_steps(points: np.ndarray, curves: CurveSet) -> tuple[np.ndarray, np.ndarray]:
    """(S, 3) float64 steps between consecutive distinct positions on every curve and (S,) their curve id.

    Zero-length steps (copies of a welded point) are dropped.
    """
    p = np.asarray(points, dtype=np.float64)[curves.order]
    cid = np.repeat(np.arange(curves.n_curves), curves.lengths)
    same = cid[1:] == cid[:-1]
    step = (p[1:] - p[:-1])[same]
    sc = cid[1:][same]
    keep = np.linalg.norm(step, axis=1) > 0
    return step[keep], sc[keep]


def turning_angles(points: np.ndarray, curves: CurveSet) -> np.ndarray:
    """(A,) float64 angles in radians between consecutive steps of every curve (0 = straight)."""
    step, sc = curve_steps(points, curves)
    if len(step) < 2:
        return np.zeros(0)
    same = sc[1:] == sc[:-1]
    a, b = step[:-1][same], step[1:][same]
    cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def step_ratios(points: np.ndarray, faces: np.ndarray, curves: CurveSet) -> np.ndarray:
    """(S,) float64 length of every step between distinct consecutive points / mean mesh edge length."""
    step, _ = curve_steps(points, curves)
    p = np.asarray(points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) == 0:
        return np.linalg.norm(step, axis=1)
    e = np.linalg.norm(p[f] - p[np.roll(f, 1, axis=1)], axis=2)
    mean = float(e[e > 0].mean()) if np.any(e > 0) else 1.0
    return np.linalg.norm(step, axis=1) / mean


def quality_summary(points: np.ndarray, faces: np.ndarray, curves: CurveSet) -> dict:
    """Median and 90th percentile turning angle (degrees) and step ratio, with curve count and mean length."""
    ang = np.degrees(turning_angles(points, curves))
    st = step_ratios(points, faces, curves)

    def pct(x: np.ndarray, q: float) -> float:
        return float(np.percentile(x, q)) if len(x) else 0.0

    return {
        "curves": curves.n_curves,
        "mean_points": float(curves.lengths.mean()) if curves.n_curves else 0.0,
        "turn_median_deg": pct(ang, 50),
        "turn_p90_deg": pct(ang, 90),
        "step_median": pct(st, 50),
        "step_p90": pct(st, 90),
        "step_max": pct(st, 100),
    }
