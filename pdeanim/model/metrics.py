"""Error metrics between original and reconstructed vertex positions.

* RMS / max of the per-vertex Euclidean distance, absolute and relative to the bounding-box diagonal of the
  first (rest) frame;
* the Karni-Gotsman error KG = 100 ||A - A_hat|| / ||A - E(A)||, E(A) each frame's centroid repeated;
* the paper's E_a and E_m (Eq. 23-24): mean and max over a curve's points of |error| / |original point|
  (division guarded: points at the origin are skipped).
"""

from __future__ import annotations

import math

import numpy as np


def bbox_diagonal(points: np.ndarray) -> float:
    """Length of the axis-aligned bounding-box diagonal of points (V, 3) (1.0 if degenerate)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if len(p) else 0.0
    return d if d > 0 else 1.0


def distances(original: np.ndarray, approx: np.ndarray) -> np.ndarray:
    """(F, V) Euclidean distance per frame and vertex of (F, V, 3) arrays."""
    return np.linalg.norm(np.asarray(original, np.float64) - np.asarray(approx, np.float64), axis=-1)


def kg_error(original: np.ndarray, approx: np.ndarray) -> float:
    """Karni-Gotsman error in percent for (F, V, 3) sequences."""
    A = np.asarray(original, np.float64)
    den = np.linalg.norm(A - A.mean(axis=1, keepdims=True))
    num = np.linalg.norm(A - np.asarray(approx, np.float64))
    return float(100.0 * num / den) if den > 0 else (0.0 if num == 0 else float("inf"))


def error_summary(original: np.ndarray, approx: np.ndarray,
                  diagonal: float | None = None) -> dict[str, float | None]:
    """rms, max, rel_rms, rel_max (to the first frame's bbox diagonal) and kg of (F, V, 3) sequences; a value
    that is undefined (e.g. kg when every vertex sits at one point) is None, so reports stay valid JSON."""
    d = distances(original, approx)
    diag = bbox_diagonal(np.asarray(original)[0]) if diagonal is None else float(diagonal)
    rms, mx = float(np.sqrt(np.mean(d * d))), float(d.max()) if d.size else 0.0
    rel_rms, rel_max = (rms / diag, mx / diag) if diag else (math.inf, math.inf)
    out = {"rms": rms, "max": mx, "rel_rms": rel_rms, "rel_max": rel_max, "kg": kg_error(original, approx),
           "diagonal": diag}
    return {k: v if math.isfinite(v) else None for k, v in out.items()}


def paper_errors(original: np.ndarray, approx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's (E_a, E_m) per frame (Eq. 23-24) for curve points original/approx (F, N, 3).

    E_a = mean_n d_n / |w_n|, E_m = max_n d_n / |w_n|; points with |w_n| = 0 are left out of both.
    """
    o = np.asarray(original, np.float64)
    d = np.linalg.norm(o - np.asarray(approx, np.float64), axis=-1)
    ref = np.linalg.norm(o, axis=-1)
    ok = ref > 0
    ratio = np.where(ok, d / np.where(ok, ref, 1.0), 0.0)
    n = ok.sum(axis=-1)
    Ea = np.where(n > 0, ratio.sum(axis=-1) / np.maximum(n, 1), 0.0)
    return Ea, ratio.max(axis=-1)
