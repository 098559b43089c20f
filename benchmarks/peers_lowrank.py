"""The PCA and keyframe peers of the compression benchmark, each at the smallest size that meets a target.

* PCA: mean + k bases + per-frame weights; bases quantised to b bits (one range per basis; b in BITS or
  ``--pca-bits``), the mean to b, b + 2 or b + 4 bits, the weights to 16 bits, each array zstd -19, faces
  with meshoptimizer's index codec. For each setting k is the smallest that meets the target (bisection on
  the decoded frames' error), at each yardstick (rel-RMS alone; rel-RMS and rel-max <= 3x the target); the
  smallest file over the settings is the peer.
* keyframes (a floor reference): K evenly spaced frames quantised to b bits (one range per axis over the
  whole sequence), zstd -19, linear interpolation in between; K the smallest that meets the target.
"""

from __future__ import annotations

import numpy as np
from peers_common import WeldedInput, faces_code, pack_payload, quantise, result, smallest_meeting

from pdeanim.fit.heldout import linear_interpolation
from pdeanim.model.metrics import bbox_diagonal

BITS = (8, 10, 12, 14, 16)
QUICK_BITS = (12, 16)
KEYFRAME_BITS = (8, 10, 12, 14, 16)
SHORTLIST = 2
"""Per target, the settings whose zstd -3 size is among the SHORTLIST smallest are sized at zstd -19."""


class PcaModel:
    """The SVD of the frames and its quantised parts: the mean at ``mean_bits`` (one range per axis), the
    bases at ``bits`` (one range per basis), the weights at 16 bits (one range per basis)."""

    def __init__(self, X: np.ndarray, counts: np.ndarray | None = None) -> None:
        self.X = X
        self.counts = None if counts is None else np.asarray(counts, np.float64)
        """Vertices per point of welded trajectories: the errors weigh each point as the source's vertices."""
        F, V = X.shape[:2]
        A = X.reshape(F, -1)
        self.mean = A.mean(0).reshape(V, 3)
        U, s, Vt = np.linalg.svd(A - A.mean(0), full_matrices=False)
        self.kmax = max(1, min(F - 1, len(s)))
        self.qw, self.W_dq, self.rw = quantise(U[:, : self.kmax] * s[: self.kmax], axis=0, bits=16)
        self.B = Vt[: self.kmax]
        self.diag = bbox_diagonal(X[0])
        self._means: dict[int, tuple] = {}
        self._bases: dict[int, tuple] = {}
        self._errors: dict[tuple[int, int, int], tuple[float, float]] = {}
        self._X32 = self._W32 = None

    def mean_q(self, bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(codes, dequantised flat, ranges) of the mean at ``bits``."""
        if bits not in self._means:
            q, dq, r = quantise(self.mean, axis=0, bits=bits)
            self._means[bits] = (q, dq.reshape(-1), r)
        return self._means[bits]

    def bases_q(self, bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(codes, dequantised, ranges) of every basis at ``bits``."""
        if bits not in self._bases:
            self._bases[bits] = quantise(self.B, axis=1, bits=bits)
        return self._bases[bits]

    def approx(self, k: int, bits: int, mean_bits: int) -> np.ndarray:
        """Frames decoded from the quantised mean and k quantised bases."""
        flat = self.mean_q(mean_bits)[1] + self.W_dq[:, :k] @ self.bases_q(bits)[1][:k]
        return flat.reshape(self.X.shape)

    def errors(self, k: int, bits: int, mean_bits: int) -> tuple[float, float]:
        """(rel-RMS, rel-max) of the decoded frames (cached: the searches of both yardsticks share them)."""
        key = (k, bits, mean_bits)
        if key not in self._errors:  # in float32: the searches evaluate many k (errors far above 1e-7)
            if self._X32 is None:
                self._X32, self._W32 = self.X.astype(np.float32), self.W_dq.astype(np.float32)
            flat = (self.mean_q(mean_bits)[1].astype(np.float32)
                    + self._W32[:, :k] @ self.bases_q(bits)[1][:k].astype(np.float32))
            d = np.linalg.norm(flat.reshape(self.X.shape) - self._X32, axis=-1)
            ms = np.mean(d * d) if self.counts is None else np.mean(d * d @ self.counts) / self.counts.sum()
            self._errors[key] = (float(np.sqrt(ms)) / self.diag, float(d.max()) / self.diag)
        return self._errors[key]

    def rel_rms(self, k: int, bits: int, mean_bits: int) -> float:
        """rel-RMS of the decoded frames."""
        return self.errors(k, bits, mean_bits)[0]

    def meets(self, k: int, bits: int, mean_bits: int, target: float, max_ratio: float | None) -> bool:
        """rel-RMS <= target, and rel-max <= max_ratio x target when given."""
        rms, mx = self.errors(k, bits, mean_bits)
        return rms <= target and (max_ratio is None or mx <= max_ratio * target)

    def arrays(self, k: int, bits: int, mean_bits: int) -> dict[str, np.ndarray]:
        """What a PCA file holds (faces added by the caller)."""
        qm, _, rm = self.mean_q(mean_bits)
        qb, _, rb = self.bases_q(bits)
        return {"mean": qm, "mean_range": rm, "bases": qb[:k], "bases_range": rb[:, :k],
                "weights": self.qw[:, :k], "weights_range": self.rw[:, :, :k]}


def zstd3_size(arrays: dict[str, np.ndarray]) -> int:
    """A quick size estimate (zstd -3 of each array) used to shortlist settings before zstd -19."""
    import zstandard

    c = zstandard.ZstdCompressor(level=3)
    return sum(len(c.compress(np.ascontiguousarray(a).tobytes())) for a in arrays.values())


MAX_RATIO = 3.0
"""The stricter yardstick of issue 30: rel-max at most this multiple of the target (as the clip keeps it)."""


def pca_settings(m: PcaModel, targets: tuple[float, ...], quick: bool,
                 bits_tried: tuple[int, ...] | None = None) -> dict[tuple[float, float | None], list[tuple]]:
    """Per target and yardstick (rel-RMS alone, or also rel-max <= MAX_RATIO x target), the (bits, mean_bits,
    k) settings that meet it with the smallest k for their bits, ordered by estimated size."""
    found: dict[tuple[float, float | None], list[tuple]] = {(t, mr): [] for t in targets
                                                            for mr in (None, MAX_RATIO)}
    for bits in QUICK_BITS if quick else (bits_tried or BITS):
        for mean_bits in sorted({min(16, bits + d) for d in ((0, 4) if quick else (0, 2, 4))}):
            for t, mr in found:
                k = smallest_meeting(1, m.kmax, lambda k, b=bits, mb=mean_bits, t=t, mr=mr:
                                     m.meets(k, b, mb, t, mr))
                if k is not None:
                    found[(t, mr)].append((zstd3_size(m.arrays(k, bits, mean_bits)), bits, mean_bits, k))
    return {key: [c[1:] for c in sorted(v)] for key, v in found.items()}


def method_pca(X: np.ndarray, faces: np.ndarray, targets: tuple[float, ...], quick: bool,
               bits_tried: tuple[int, ...] | None = None) -> list[dict]:
    """For each target and yardstick (rel-RMS alone; rel-RMS and rel-max <= 3x the target), the smallest PCA
    file that meets it (bits of the bases and the mean searched, k by bisection), sized at zstd -19 for the
    shortlisted settings; on the welded trajectories (seam duplicates merged, the remap in the file)."""
    w = WeldedInput(X, faces)
    m = PcaModel(w.X, np.bincount(w.point_of, minlength=w.X.shape[1]) if w.merged else None)
    fc = faces_code(w.faces, w.X.shape[1])
    rows, done = [], set()
    for settings in pca_settings(m, targets, quick, bits_tried).values():
        for bits, mean_bits, k in settings[:SHORTLIST]:
            if (bits, mean_bits, k) in done:
                continue
            done.add((bits, mean_bits, k))
            blob = pack_payload("pca", {"faces": fc, **w.arrays(), **m.arrays(k, bits, mean_bits)})
            rows.append(result("pca", f"k={k}, bases {bits}-bit, mean {mean_bits}-bit"
                               + (f", welded {w.X.shape[1]} points" if w.merged else ""), blob,
                               w.expand(m.approx(k, bits, mean_bits)), X, k=k, bits=bits,
                               mean_bits=mean_bits))
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
    """For each target, the smallest keyframe file that meets it (bits searched, the fewest frames by
    bisection), sized at zstd -19 for the shortlisted settings."""
    F = len(X)
    diag = bbox_diagonal(X[0])
    fc = faces_code(faces, X.shape[1])

    def rel_rms(count: int, bits: int) -> float:
        d = np.linalg.norm(keyframe_approx(X, count, bits)[0] - X, axis=-1)
        return float(np.sqrt(np.mean(d * d))) / diag

    rows, done = [], set()
    for t in targets:
        found = []
        for bits in (12, 16) if quick else KEYFRAME_BITS:
            n = smallest_meeting(2, F, lambda n, b=bits, t=t: rel_rms(n, b) <= t)
            if n is not None:
                found.append((zstd3_size(keyframe_approx(X, n, bits)[1]), bits, n))
        for _, bits, n in sorted(found)[:SHORTLIST]:
            if (bits, n) in done:
                continue
            done.add((bits, n))
            approx, arrays = keyframe_approx(X, n, bits)
            blob = pack_payload("keyframes", {"faces": fc, **arrays})
            rows.append(result("keyframes", f"{n} frames {bits}-bit", blob, approx, X, bits=bits))
    return rows
