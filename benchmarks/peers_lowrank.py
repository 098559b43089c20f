"""The PCA and keyframe peers of the compression benchmark, each at the smallest size that meets a target.

* PCA: mean + k bases + per-frame weights; bases quantised to b bits (one range per basis), weights and mean
  to 16 bits, each array zstd -19, faces with meshoptimizer's index codec. For each b, k is the smallest that
  meets the target (bisection on the quantised reconstruction's error).
* keyframes (a floor reference): K evenly spaced frames quantised to b bits (one range per axis over the
  whole sequence), zstd -19, linear interpolation in between; K the smallest that meets the target.
"""

from __future__ import annotations

import numpy as np
from peers_common import faces_code, pack_payload, quantise, result, smallest_meeting

from pdeanim.model.heldout import linear_interpolation
from pdeanim.model.metrics import bbox_diagonal

BITS = (8, 10, 12, 14, 16)
QUICK_BITS = (12, 16)
KEYFRAME_BITS = (10, 12, 14, 16)


class PcaModel:
    """The SVD of the frames and, per bit depth, the quantised parts a decoder would get."""

    def __init__(self, X: np.ndarray) -> None:
        self.X = X
        F, V = X.shape[:2]
        A = X.reshape(F, -1)
        self.mean = A.mean(0)
        U, s, Vt = np.linalg.svd(A - self.mean, full_matrices=False)
        self.kmax = min(F - 1, len(s)) if F > 1 else 1
        self.W, self.B = U[:, : self.kmax] * s[: self.kmax], Vt[: self.kmax]
        self.qm, mean_dq, self.rm = quantise(self.mean.reshape(V, 3), axis=0, bits=16)
        self.mean_dq = mean_dq.reshape(-1)
        self.qw, self.W_dq, self.rw = quantise(self.W, axis=0, bits=16)
        self.diag = bbox_diagonal(X[0])

    def approx(self, k: int, B_dq: np.ndarray) -> np.ndarray:
        """Frames decoded from k quantised bases."""
        return (self.mean_dq + self.W_dq[:, :k] @ B_dq[:k]).reshape(self.X.shape)

    def rel_rms(self, k: int, B_dq: np.ndarray) -> float:
        """rel-RMS of the decoded frames with k bases."""
        d = np.linalg.norm(self.approx(k, B_dq) - self.X, axis=-1)
        return float(np.sqrt(np.mean(d * d))) / self.diag


def method_pca(X: np.ndarray, faces: np.ndarray, targets: tuple[float, ...], quick: bool) -> list[dict]:
    """For each bit depth and target, the smallest k that meets the target, as a file (and on the wire)."""
    m = PcaModel(X)
    fc = faces_code(faces, X.shape[1])
    rows, seen = [], set()
    for bits in QUICK_BITS if quick else BITS:
        qb, B_dq, rb = quantise(m.B, axis=1, bits=bits)
        for target in targets:
            k = smallest_meeting(1, m.kmax, lambda k, B_dq=B_dq, target=target: m.rel_rms(k, B_dq) <= target)
            if k is None or (bits, k) in seen:
                continue
            seen.add((bits, k))
            blob = pack_payload("pca", {"faces": fc, "mean": m.qm, "mean_range": m.rm, "bases": qb[:k],
                                        "bases_range": rb[:, :k], "weights": m.qw[:, :k],
                                        "weights_range": m.rw[:, :, :k]})
            rows.append(result("pca", f"k={k} bases {bits}-bit", blob, m.approx(k, B_dq), X, k=k, bits=bits))
    return rows


def keyframe_approx(X: np.ndarray, count: int, bits: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Linear interpolation of ``count`` evenly spaced quantised frames, and the arrays a file would hold."""
    F = len(X)
    keep = np.unique(np.rint(np.linspace(0, F - 1, count)).astype(int))
    q, dq, r = quantise(X[keep], axis=(0, 1), bits=bits)
    times = np.arange(F, dtype=np.float64)
    approx = linear_interpolation(times[keep], dq, times) if len(keep) > 1 else np.broadcast_to(dq, X.shape)
    return approx, {"frames": q, "range": r, "frame_index": keep.astype(np.uint16)}


def method_keyframes(X: np.ndarray, faces: np.ndarray, targets: tuple[float, ...], quick: bool) -> list[dict]:
    """For each bit depth and target, the fewest evenly spaced keyframes that meet the target."""
    F = len(X)
    diag = bbox_diagonal(X[0])
    fc = faces_code(faces, X.shape[1])
    rows, seen = [], set()

    def rel_rms(count: int, bits: int) -> float:
        d = np.linalg.norm(keyframe_approx(X, count, bits)[0] - X, axis=-1)
        return float(np.sqrt(np.mean(d * d))) / diag

    for bits in (16,) if quick else KEYFRAME_BITS:
        for target in targets:
            n = smallest_meeting(2, F, lambda n, bits=bits, target=target: rel_rms(n, bits) <= target)
            if n is None or (bits, n) in seen:
                continue
            seen.add((bits, n))
            approx, arrays = keyframe_approx(X, n, bits)
            blob = pack_payload("keyframes", {"faces": fc, **arrays})
            rows.append(result("keyframes", f"{n} frames {bits}-bit", blob, approx, X, bits=bits))
    return rows
