"""A low-rank time basis shared by the knot tracks of all curves (docs/format.md §3.4).

The knots (S+1, C, 3, 4) are C * 12 time tracks of S+1 values. Where the motion is a blend of a few shapes
(morph targets, a few dominant modes), the tracks span only a few directions in time, so ``knots[s, c, w, k]
~ sum_j weights[j, c, w, k] * basis[j, s]`` with r << S+1 stores r values per track plus r * (S+1) shared
ones. The basis is the leading right singular vectors of the tracks weighted by how much each moves the
vertices. Weights and a residual track are integer codes on the same power-of-two step as plain knot tracks,
and the residual takes whatever the basis misses, so every knot is rounded exactly as well as in plain tracks
(at most half a step) while tracks that follow the basis store residual codes of about zero.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

try:
    from numba import njit

    COMPILED = True
except ImportError:  # pragma: no cover - numba is a pinned dependency; this keeps the numpy path usable
    COMPILED = False

from ..curveset import CurveSet
from .quantise import MAX_CODE, pair_max, vertex_basis

TRUNCATION_SHARES = (1.0, 0.5, 0.25)
"""Ranks tried: for each share, the smallest rank whose truncation alone moves the vertices by at most that
share of what rounding the knots to their steps does (RMS, estimated; the residual takes the truncation back
where it exceeds half a step); the writer keeps the smallest encoding."""
MAX_RANK_SHARE = 0.75
"""A rank above this share of the knot count saves too little to be worth trying."""
MAX_RANK = 96
"""Nor above this many shared tracks: decoding costs r multiply-adds per knot value."""


@dataclass
class KnotBasis:
    """Integer weights (r, C, 3, 4) and residual codes (S+1, C, 3, 4), both int64 on the knot steps (C, 3),
    and the basis (r, S+1) float32."""

    weights: np.ndarray
    residual: np.ndarray
    basis: np.ndarray

    @property
    def rank(self) -> int:
        """Number of basis tracks r."""
        return int(self.basis.shape[0])


def basis_part(codes: np.ndarray, steps: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(S+1, C, 3, 4) float64 sum over j (ascending, from 0) of (code * step) * basis[j, s]: the decoder's
    exact arithmetic (each product and partial sum rounded as an IEEE double, no fused multiply-add)."""
    q = np.asarray(codes, np.float64) * np.asarray(steps, np.float64)[None, :, :, None]  # (r, C, 3, 4)
    b = np.asarray(basis, np.float64)  # (r, S+1)
    acc = np.zeros((b.shape[1], *q.shape[1:]))
    if COMPILED:
        _ordered_sum(np.ascontiguousarray(q.reshape(len(q), -1)), np.ascontiguousarray(b),
                     acc.reshape(b.shape[1], -1))
        return acc
    for j in range(len(b)):
        acc += b[j][:, None, None, None] * q[j][None]
    return acc


def _ordered_sum(q: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out[s, t] = sum over j ascending of q[j, t] * b[j, s], each product and sum a rounded double (compiled
    without fast-math: no contraction into fused multiply-adds, so the numpy path's bits)."""
    for s in range(out.shape[0]):
        for t in range(out.shape[1]):
            acc = 0.0
            for j in range(q.shape[0]):
                acc += q[j, t] * b[j, s]
            out[s, t] = acc


if COMPILED:
    _ordered_sum = njit(cache=True, nogil=True, boundscheck=False)(_ordered_sum)


def knots_from_basis(codes: np.ndarray, residual: np.ndarray, steps: np.ndarray, basis: np.ndarray
                     ) -> np.ndarray:
    """Knots (S+1, C, 3, 4) float32 = float32(basis part + residual * step), in doubles (§3.4)."""
    acc = basis_part(codes, steps, basis)
    acc += np.asarray(residual, np.float64) * np.asarray(steps, np.float64)[None, :, :, None]
    with np.errstate(over="ignore"):  # a value beyond float32 becomes inf, which the reader refuses
        return acc.astype(np.float32)


@dataclass
class TrackSpectrum:
    """The knot tracks (C * 12, K) float64 of a fit, how much a unit error of each moves the vertices
    (weight (C, 3, 4)), and the right singular vectors vt (K, K) and tail energies (K + 1,) of the weighted
    tracks: what the basis candidates need besides the steps, computed once per fit (the rate control encodes
    the same knots at several steps)."""

    knots: np.ndarray
    tracks: np.ndarray
    weight: np.ndarray
    vt: np.ndarray
    tail: np.ndarray


def track_spectrum(curves: CurveSet, u: np.ndarray, family: np.ndarray, m: np.ndarray, D: np.ndarray,
                   knots: np.ndarray) -> TrackSpectrum | None:
    """The weighted spectrum of the knot tracks (None when there are too few knots or no curves)."""
    knots = np.asarray(knots, np.float64)
    K, C = knots.shape[0], curves.n_curves
    if K < 3 or C == 0:
        return None
    cid, B = vertex_basis(curves, u, family, D)
    V = max(len(u), 1)
    weight = np.zeros((C, 3, 4))
    np.add.at(weight, cid, B * B)
    weight *= (pair_max(family, m) ** 2)[..., None] / V  # how much a unit track error moves the vertices
    tracks = np.moveaxis(knots, 0, -1).reshape(-1, K)  # (C * 12, K)
    weighted = np.sqrt(weight).reshape(-1, 1) * tracks
    # the spectrum from the (K, K) Gram matrix: one matrix product (~3x faster than a QR of the C * 12 rows);
    # it squares the condition number, which loses only energies below ~1e-16 of the largest, far under any
    # rounding the basis is weighed against (the weights themselves are solved by QR, in _on_basis)
    energy, vectors = np.linalg.eigh(weighted.T @ weighted)
    order = np.argsort(energy)[::-1]
    sigma2, vt = np.maximum(energy[order], 0.0), vectors[:, order].T
    tail = np.concatenate([np.cumsum(sigma2[::-1])[::-1], [0.0]]) / K  # tail[r]: drop r..
    return TrackSpectrum(knots, tracks, weight, vt, tail)


def basis_candidates(spectrum: TrackSpectrum | None, steps: np.ndarray, loop: bool) -> Iterator[KnotBasis]:
    """Encodings of the knots on a basis, one per distinct rank of TRUNCATION_SHARES, below MAX_RANK_SHARE of
    the knot count, made one at a time (each holds integer tracks as large as the knots). Every knot decodes
    within half a step of ``steps`` (C, 3), as plain tracks do. ``loop`` keeps the basis's first and last
    columns equal, so equal first and last knots stay equal."""
    if spectrum is None:
        return
    K = spectrum.knots.shape[0]
    rounding = float(np.sum(spectrum.weight * (np.asarray(steps, np.float64) ** 2)[..., None])) / 12.0
    ranks = set()
    for share in TRUNCATION_SHARES:
        r = int(np.argmax(spectrum.tail <= share**2 * rounding))
        if 1 <= r <= min(MAX_RANK_SHARE * K, MAX_RANK) and r not in ranks:
            ranks.add(r)
            found = _on_basis(spectrum.knots, spectrum.tracks, spectrum.vt[:r], steps, loop)
            if found is not None:
                yield found


def basis_of_rank(spectrum: TrackSpectrum, steps: np.ndarray, loop: bool, rank: int) -> KnotBasis | None:
    """The knots on the leading ``rank`` tracks of the spectrum (None where a code would overflow)."""
    return _on_basis(spectrum.knots, spectrum.tracks, spectrum.vt[:rank], steps, loop)


def _on_basis(knots: np.ndarray, tracks: np.ndarray, rows: np.ndarray, steps: np.ndarray, loop: bool
              ) -> KnotBasis | None:
    """The knots on the basis ``rows`` (r, K): least-squares weights rounded to the steps, and the rounded
    residual of what the decoder's basis part leaves; None if a code would leave the int32-safe range."""
    r, K = rows.shape
    C = steps.shape[0]
    basis = rows.astype(np.float32)
    if loop:
        basis[:, -1] = basis[:, 0]
    b = basis.astype(np.float64)
    q, tri = np.linalg.qr(b.T)  # (K, r): the rows are orthonormal up to float32 rounding, so well posed
    coef = solve_triangular(tri, q.T @ tracks.T).T  # (C * 12, r) least squares, ~10x faster than lstsq's SVD
    h = np.asarray(steps, np.float64)
    weights = np.rint(np.moveaxis(coef.reshape(C, 3, 4, r), -1, 0) / h[None, :, :, None])
    if not np.all(np.abs(weights) <= MAX_CODE):
        return None
    weights = weights.astype(np.int64)
    # the writer's basis part by one matrix product: it may differ from the decoder's ordered sum (§3.4) in
    # the last bit, which moves a decoded knot by that bit on top of its half step
    approx = (basis.astype(np.float64).T @ (weights * h[..., None]).reshape(r, -1)).reshape(knots.shape)
    residual = np.rint((knots - approx) / h[None, :, :, None])
    if not np.all(np.abs(residual) <= MAX_CODE):
        return None
    return KnotBasis(weights, residual.astype(np.int64), basis)


SHARED_BITS = 8
"""A clip's shared weights (:class:`SharedWeights`) are rounded to one power-of-two grid this many bits below
the largest weight (AnimatedMorphSphere in 2 windows: 12 bits 9,256 B, 10 bits 8,832 B, 8 bits 8,360 B, its
error 0.08, 0.12 and 0.36 of the target; the windows' rate control measures what the grid leaves) ...
"""
SHARED_SCALE = 2.0 ** (SHARED_BITS + 1)
"""... and the weights of shapes of RMS size (as the knots they span) are stored this many times larger, so
that the grid is about twice the largest item's motion, no finer than a useful knot step: a window's steps
then stay its own and the weights are whole codes on them (with trailing zero bits)."""


@dataclass
class SharedWeights:
    """Weights that every window of a windowed fit may put its knots on (one set per clip, so that the
    joined clip stores them once, not once per window): integer codes (r, C, 3, 4) on a power-of-two grid
    (C, 3), the same for every item (0 where the item has no weight: small items get small codes). A
    window's knot steps are made no coarser than the grid where it uses them, so that the weights are whole
    codes on every window's steps and on the finest of them (the joined clip's)."""

    codes: np.ndarray
    grid: np.ndarray

    @property
    def rank(self) -> int:
        return int(self.codes.shape[0])

    @classmethod
    def of(cls, values: np.ndarray) -> SharedWeights:
        """The shared weights of shapes ``values`` (r, C, 3, 4) of RMS size: SHARED_SCALE times them, on a
        grid SHARED_BITS below the largest."""
        values = np.asarray(values, np.float64) * SHARED_SCALE
        largest = np.abs(values).max(axis=(0, 3)) if len(values) else np.zeros(values.shape[1:3])
        largest = np.where(largest > 0, largest.max(initial=0.0), 0.0)  # one grid: small items, small codes
        with np.errstate(divide="ignore"):
            grid = np.where(largest > 0, np.exp2(np.floor(np.log2(np.where(largest > 0, largest, 1.0)))
                                                  - SHARED_BITS), 0.0)
        codes = np.rint(values / np.where(grid > 0, grid, 1.0)[None, :, :, None]).astype(np.int64)
        return cls(codes, grid.astype(np.float32).astype(np.float64))

    def steps(self, steps: np.ndarray) -> np.ndarray:
        """Knot steps (C, 3) no coarser than the grid where the weights are not zero."""
        steps = np.asarray(steps, np.float32)
        return np.where(self.grid > 0, np.minimum(steps, self.grid), steps).astype(np.float32)

    def values(self, rank: int) -> np.ndarray:
        """(rank, C, 3, 4) float64 the leading ``rank`` weights."""
        return self.codes[:rank] * self.grid[None, :, :, None]


def shared_ranks(spectrum: TrackSpectrum | None, shared: SharedWeights | None, steps: np.ndarray
                 ) -> list[int]:
    """Ranks worth trying on ``shared`` weights: for each of TRUNCATION_SHARES the fewest leading weights
    whose least-squares fit leaves at most that share of the knots' rounding (as :func:`basis_candidates`),
    or all of them where none does; at most MAX_RANK_SHARE of the knot count."""
    if spectrum is None or shared is None or shared.rank == 0:
        return []
    K = spectrum.knots.shape[0]
    most = min(shared.rank, int(MAX_RANK_SHARE * K), MAX_RANK)
    if most < 1:
        return []
    a, b = _weighted(spectrum, shared.values(most))
    q, _ = np.linalg.qr(a)
    captured = ((q.T @ b) ** 2).sum(axis=1)  # (most,)
    tail = (float((b * b).sum()) - np.concatenate([[0.0], np.cumsum(captured)])) / K  # tail[r]: after r
    rounding = float(np.sum(spectrum.weight * (np.asarray(steps, np.float64) ** 2)[..., None])) / 12.0
    ranks = []
    for share in TRUNCATION_SHARES:
        reached = np.flatnonzero(tail[1:] <= share**2 * rounding)
        r = int(reached[0]) + 1 if len(reached) else most
        if r not in ranks:
            ranks.append(r)
    return ranks


def _weighted(spectrum: TrackSpectrum, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, r) weights and (T, K) tracks, each track scaled by how much it moves the vertices."""
    w = np.sqrt(spectrum.weight.reshape(-1, 1))
    return w * values.reshape(len(values), -1).T, w * spectrum.tracks


def on_shared(spectrum: TrackSpectrum, shared: SharedWeights, steps: np.ndarray, loop: bool, rank: int
              ) -> tuple[KnotBasis, np.ndarray] | None:
    """(the knots on the leading ``rank`` shared weights, the knot steps it takes: ``steps`` made no coarser
    than the weights' grid): the basis (r, S+1) is the least-squares time tracks of the fixed weights, the
    residual what the decoder's basis part leaves, rounded; None where a code would overflow."""
    steps = shared.steps(steps)
    h = np.asarray(steps, np.float64)
    values = shared.values(rank)
    g = np.where(shared.grid > 0, shared.grid, 1.0)
    weights = shared.codes[:rank] * np.rint(g / h)[None, :, :, None].astype(np.int64)
    weights[:, shared.grid <= 0] = 0
    if not np.all(np.abs(weights) <= MAX_CODE):
        return None
    a, b = _weighted(spectrum, values)
    basis = np.linalg.lstsq(a, b, rcond=1e-10)[0].astype(np.float32)  # (r, K)
    if loop:
        basis[:, -1] = basis[:, 0]
    knots = spectrum.knots
    approx = (basis.astype(np.float64).T @ (weights * h[..., None]).reshape(rank, -1)).reshape(knots.shape)
    residual = np.rint((knots - approx) / h[None, :, :, None])
    if not np.all(np.abs(residual) <= MAX_CODE):
        return None
    return KnotBasis(weights, residual.astype(np.int64), basis), steps
