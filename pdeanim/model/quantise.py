"""Error-bounded integer coding of the dynamic-PDE arrays (docs/format.md §3.2-3.4).

Every quantised quantity is an integer times a step; the steps are chosen so that rounding moves no vertex
coordinate by more than a tolerance. Integer tracks are stored as zigzag-coded differences, which are small
where the data is smooth (along time for knots, along the curves for rest positions and u) and compress well.
"""

from __future__ import annotations

import numpy as np

from ..curveset import CurveSet
from .families import SPACE_KINDS, space_basis

U_STEPS = 2.0 ** -np.arange(12, 21)
"""Candidate steps of the curve parameter u in [0, 1]: the coarsest that holds every u exactly (the fit puts
u on the 2^-12 grid), else 2^-20 (1e-6: far below what moves a vertex visibly)."""
MAX_CODE = 2**28
"""Largest magnitude of a knot code (so that differences fit int32); the step is coarsened beyond it."""


def zigzag_deltas(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """uint32 zigzag codes of the differences of integer array ``q`` along ``axis`` (the first element
    against 0): small magnitudes of either sign become small unsigned numbers."""
    return zigzag(_int32(np.diff(np.asarray(q, np.int64), axis=axis, prepend=0)))


def _int32(d: np.ndarray) -> np.ndarray:
    """int64 differences as int32; raises ValueError where they do not fit in 32 bits."""
    if d.size and (d.min() < -(2**31) or d.max() >= 2**31):
        raise ValueError("integer differences do not fit in 32 bits")
    return d


def undo_zigzag_deltas(z: np.ndarray, axis: int = 0) -> np.ndarray:
    """Inverse of :func:`zigzag_deltas`: the int64 running sums of the decoded differences."""
    return np.cumsum(unzigzag(z), axis=axis)


def zigzag(d: np.ndarray, in_place: bool = False) -> np.ndarray:
    """uint32 zigzag codes of int32-range integers (0, -1, 1, -2, 2 -> 0, 1, 2, 3, 4): the one zigzag encoder
    of the format. ``in_place`` with an int32 array reuses its buffer (the codes of a long clip's knots)."""
    if not (in_place and isinstance(d, np.ndarray) and d.dtype == np.int32):
        d = np.asarray(d, np.int64).astype(np.int32)
    negative = d < 0
    z = d.view(np.uint32)
    z <<= np.uint32(1)
    np.bitwise_xor(z, np.uint32(0xFFFFFFFF), out=z, where=negative)
    return z


def unzigzag(z: np.ndarray) -> np.ndarray:
    """int64 values of uint32 zigzag codes (inverse of :func:`zigzag`)."""
    z = np.asarray(z, np.uint32)
    return (z >> np.uint32(1)).astype(np.int64) ^ -(z & np.uint32(1)).astype(np.int64)


def encode_faces(faces: np.ndarray, order: np.ndarray) -> np.ndarray:
    """(T, 3) uint32 codes of the triangles in curve-rank space (rank = position in ``order``), in a canonical
    order: each triangle turned (winding kept) to start at its lowest rank, rows sorted; column 0 holds the
    zigzag differences of the first ranks along the rows, columns 1-2 the zigzag rank offsets from it.
    Neighbouring triangles share curves, so the numbers are small."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    if not len(faces):
        return np.zeros((0, 3), np.uint32)
    rank = np.empty(len(order), np.int64)
    rank[np.asarray(order, np.int64)] = np.arange(len(order))
    r = rank[faces]
    first = np.argmin(r, axis=1)[:, None]
    r = np.take_along_axis(r, (first + np.arange(3)) % 3, axis=1)
    r = r[np.lexsort((r[:, 2], r[:, 1], r[:, 0]))]
    return np.stack([zigzag_deltas(r[:, 0]), zigzag(r[:, 1] - r[:, 0]), zigzag(r[:, 2] - r[:, 0])], axis=1)


def decode_faces(codes: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_faces`: (T, 3) int64 vertex indices (canonical triangle order); -1 marks a
    rank outside the vertices."""
    codes = np.asarray(codes, np.uint32).reshape(-1, 3)
    a = undo_zigzag_deltas(codes[:, 0])
    r = np.stack([a, a + unzigzag(codes[:, 1]), a + unzigzag(codes[:, 2])], axis=1)
    order = np.asarray(order, np.int64)
    ok = (r >= 0) & (r < len(order))
    return np.where(ok, order[np.where(ok, r, 0)], -1)


def u_step(u: np.ndarray) -> float:
    """The coarsest of U_STEPS that represents every u exactly (else the finest)."""
    u = np.asarray(u, np.float64)
    for step in U_STEPS:
        if np.array_equal(np.rint(u / step) * step, u):
            return float(step)
    return float(U_STEPS[-1])


def power_of_two_step(tolerance: float) -> float:
    """The largest power of two whose rounding error (half a step) is at most ``tolerance``."""
    return float(2.0 ** np.floor(np.log2(2.0 * tolerance)))


def rest_origin_step(rest: np.ndarray, tolerance: float) -> tuple[np.ndarray, float]:
    """(origin (3,), step) of the rest positions: the box's low corner and a power-of-two step."""
    rest = np.asarray(rest, np.float64)
    origin = rest.min(axis=0) if len(rest) else np.zeros(3)
    extent = float(np.ptp(rest, axis=0).max()) if len(rest) else 0.0
    step = power_of_two_step(max(tolerance, extent * 2.0**-30, 1e-30))
    return origin, step


def dequantise(q: np.ndarray, step: float | np.ndarray, origin: float | np.ndarray = 0.0) -> np.ndarray:
    """float32(origin + q * step), computed in float64: the decoder's exact arithmetic."""
    return (np.asarray(origin, np.float64) + np.asarray(q, np.float64) * np.asarray(step, np.float64)).astype(
        np.float32)


def vertex_basis(curves: CurveSet, u: np.ndarray, family: np.ndarray, D: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(curve id (V,), space basis (V, 3, 4)) of every vertex and coordinate."""
    V = len(u)
    cid, _ = curves.curve_of_vertex(V)
    uu, DD = np.asarray(u, np.float64), np.asarray(D, np.float64)[cid]
    kind_v = (np.asarray(family)[0] % 2)[cid]
    B = np.zeros((V, 3, 4))
    for i, kind in enumerate(SPACE_KINDS):
        sel = kind_v == i
        if np.any(sel):
            B[sel] = space_basis(uu[sel][:, None], DD[sel], kind)[:, 0, :]
    return cid, B


CUBIC_PAIR_MAX = 1.5
"""Least bound taken for the summed absolute knot weights of a natural-spline track (h00 + h01 = 1 and the
tangent terms add up to about half of it); the writer uses the larger of this and the weights' sum at the
clip's frames."""


def pair_max(family: np.ndarray, m: np.ndarray, tangents: np.ndarray | None = None,
             cubic_max: float = CUBIC_PAIR_MAX) -> np.ndarray:
    """(C, 3) bound of phi0 + phi1 over every segment: 1 for exp and linear time, 1 / cos(m/2) for trig, and
    ``cubic_max`` (the cubic's summed absolute knot weights) for items with tangents (C, 3)."""
    m_trig = np.where(np.asarray(family) >= 2, np.asarray(m, np.float64), 0.0).max(axis=0)
    bound = 1.0 / np.cos(np.minimum(m_trig, np.pi - 1e-6) / 2.0)
    if tangents is None:
        return bound
    return np.where(np.asarray(tangents) > 0, np.maximum(bound, cubic_max), bound)


def knot_steps(curves: CurveSet, u: np.ndarray, family: np.ndarray, m: np.ndarray, D: np.ndarray,
               knots: np.ndarray, tolerance: float, tangents: np.ndarray | None = None,
               cubic_max: float = CUBIC_PAIR_MAX) -> np.ndarray:
    """(C, 3) float32 power-of-two steps of the knots, per curve and coordinate, so that rounding every knot
    to a multiple moves no vertex coordinate by more than ``tolerance``.

    A knot error of at most step/2 moves a vertex by at most step/2 * sum_k |S_k(u)| * max_tau (phi0 + phi1).
    """
    cid, B = vertex_basis(curves, u, family, D)
    sens = np.zeros((curves.n_curves, 3))
    np.maximum.at(sens, cid, np.abs(B).sum(-1))
    return _power_of_two(2.0 * tolerance / np.maximum(sens * pair_max(family, m, tangents, cubic_max), 1e-30),
                         knots)


def knot_steps_rms(curves: CurveSet, u: np.ndarray, family: np.ndarray, m: np.ndarray, D: np.ndarray,
                   knots: np.ndarray, rms: float, cap: float | np.ndarray, tangents: np.ndarray | None = None,
                   cubic_max: float = CUBIC_PAIR_MAX) -> np.ndarray:
    """(C, 3) float32 power-of-two steps whose rounding adds at most ``rms`` to the RMS vertex distance, and
    moves no vertex coordinate by more than ``cap`` (a number, or (C, 3) per curve and coordinate).

    Rounding to a step h is noise of variance h^2 / 12 per knot value; at a vertex it adds
    h^2 / 12 * sum_k S_k(u)^2 * (phi0^2 + phi1^2) to a coordinate's variance. Fewest bits for a given total:
    every curve and coordinate contributes the same share of rms^2 (each has the same number of knots).
    """
    cid, B = vertex_basis(curves, u, family, D)
    weight, reach = item_sensitivity(cid, B, curves.n_curves, pair_max(family, m),
                                     pair_max(family, m, tangents, cubic_max))
    return budget_steps(weight, reach, rms, cap, knots)


def item_sensitivity(cid: np.ndarray, B: np.ndarray, n_curves: int, pair: np.ndarray | float,
                     bound: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """(weight, reach), each (C, 3), of every item: the mean square a unit rounding noise of its knots adds
    over the vertices (sum_k S_k^2 x pair^2 / 12 / V), and the most a unit rounding of them moves a vertex
    coordinate (max over the curve of sum_k |S_k| x bound). ``pair``/``bound``: the time weights' bounds."""
    weight = np.zeros((n_curves, 3))
    np.add.at(weight, cid, (B * B).sum(-1))  # sum over the curve's vertices of sum_k S_k^2
    weight *= np.asarray(pair) ** 2 / (12.0 * max(len(cid), 1))
    sens = np.zeros((n_curves, 3))
    np.maximum.at(sens, cid, np.abs(B).sum(-1))
    return weight, sens * bound


def budget_steps(weight: np.ndarray, reach: np.ndarray, rms: float, cap: float | np.ndarray,
                 knots: np.ndarray) -> np.ndarray:
    """(C, 3) float32 power-of-two steps for an RMS budget shared evenly by the items (weight, reach of
    :func:`item_sensitivity`), none moving a vertex coordinate by more than ``cap``; ``knots`` bound the
    codes."""
    C = weight.shape[0]
    ideal = np.sqrt(rms * rms / max(3 * C, 1) / np.maximum(weight, 1e-300))
    capped = np.minimum(ideal, 2.0 * cap / np.maximum(reach, 1e-30))
    # a power of two by dithered rounding in log2 (floor(log2 x + d), d spread over [0, 1) item by item:
    # unbiased in log2), so that the total moves smoothly with rms instead of every item whose step is alike
    # doubling at the same rms (the cap is a share of the budget, so it is rounded alike: the caller measures
    # the stored clip, and refines the curves that stray past its bound)
    return _power_of_two(2.0 ** np.floor(np.log2(np.maximum(capped, 1e-300)) + dither((C, 3))), knots)


GOLDEN = 0.6180339887498949


def dither(shape: tuple[int, ...]) -> np.ndarray:
    """Offsets in [0, 1) spread evenly over the elements of ``shape`` (the golden-ratio sequence:
    deterministic, and any run of consecutive items covers [0, 1) evenly)."""
    return np.mod(np.arange(int(np.prod(shape))) * GOLDEN, 1.0).reshape(shape)


def refined_steps(steps: np.ndarray, refine: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """(C, 3) float32 power-of-two steps halved ``refine`` (C, 3) times per curve and coordinate (still coarse
    enough that every code stays within MAX_CODE)."""
    return _power_of_two(np.asarray(steps, np.float64) * 2.0 ** -np.asarray(refine, np.float64), knots)


def _power_of_two(steps: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Steps rounded down to powers of two (a byte each after compression), coarse enough that every code
    stays within MAX_CODE."""
    C = steps.shape[0]
    biggest = np.abs(np.asarray(knots, np.float64)).max(axis=(0, 3)) if len(knots) else np.zeros((C, 3))
    steps = np.maximum(steps, biggest / MAX_CODE)
    steps = np.clip(steps, np.finfo(np.float32).tiny, np.finfo(np.float32).max)
    return (2.0 ** np.floor(np.log2(steps))).astype(np.float32)


TRIAL_LEVEL = 3
"""zstd level of trial encodings (the fit's rounding search, its choice between fits, and the choice between
knot encodings): fast, and about proportional to the final level 19 sizes; only the clip that is kept is
compressed at container.ZSTD_LEVEL."""
TRACK_SAMPLE = 1 << 22
"""Codes on which the order of the track differences is chosen (evenly spaced curves, all their tracks)."""


def encode_knot_tracks(codes: np.ndarray) -> tuple[np.ndarray, int]:
    """(tracks (C, 3, 4, S+1) uint32, order): the integer knot codes (S+1, C, 3, 4) as one time track per
    curve, coordinate and coefficient, coded as zigzag differences of the order :func:`difference_order`
    chooses."""
    tracks = np.ascontiguousarray(np.moveaxis(np.asarray(codes, np.int64), 0, -1))
    order = difference_order(tracks)
    return track_codes(tracks, order), order


def knot_tracks(codes: np.ndarray, order: int) -> np.ndarray:
    """(C, 3, 4, S+1) uint32 tracks of the integer knot codes (S+1, C, 3, 4): zigzag differences of order 1
    or 2 along time."""
    return track_codes(np.moveaxis(np.asarray(codes, np.int64), 0, -1), order)


def difference_order(tracks: np.ndarray) -> int:
    """1 or 2: the order of the differences along time of integer tracks (C, 3, 4, T) that compresses
    smaller at TRIAL_LEVEL (order 2 wins where the knots move smoothly), judged on evenly spaced curves
    holding at most TRACK_SAMPLE codes (all of them in most clips): the one choice of every writer."""
    import zstandard

    compress = zstandard.ZstdCompressor(level=TRIAL_LEVEL).compress

    def size(z: np.ndarray) -> int:
        return len(compress(np.ascontiguousarray(z)))

    C = tracks.shape[0]
    picked = np.linspace(0, C - 1, max(1, min(C, TRACK_SAMPLE // max(tracks[0].size, 1))))
    first = np.diff(np.asarray(tracks[np.unique(picked.astype(np.int64))], np.int64), axis=-1, prepend=0)
    second = np.diff(first, axis=-1, prepend=0)
    return 1 if size(zigzag(first)) <= size(zigzag(second)) else 2


def track_codes(tracks: np.ndarray, order: int, in_place: bool = False) -> np.ndarray:
    """(C, 3, 4, T) uint32 zigzag differences of order 1 or 2 along time of integer tracks; ``in_place`` with
    an int32 array computes them in its buffer (codes stay within MAX_CODE, so their differences fit)."""
    if in_place and tracks.dtype == np.int32:
        for _ in range(order):
            for t in range(tracks.shape[-1] - 1, 0, -1):  # backwards: each difference reads the value before
                tracks[..., t] -= tracks[..., t - 1]
        return zigzag(tracks, in_place=True)
    d = np.asarray(tracks, np.int64)
    for _ in range(order):
        d = _int32(np.diff(d, axis=-1, prepend=0))
    return zigzag(d)


def decode_knot_tracks(tracks: np.ndarray, order: int) -> np.ndarray:
    """Inverse of :func:`encode_knot_tracks`: codes (S+1, C, 3, 4) int64."""
    q = undo_zigzag_deltas(tracks, axis=-1)
    if order == 2:
        q = np.cumsum(q, axis=-1)
    return np.moveaxis(q, -1, 0)


def quantise_knots(knots: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Integer codes (S+1, C, 3, 4) int64 of the knots for (C, 3) steps."""
    return np.rint(np.asarray(knots, np.float64) / np.asarray(steps, np.float64)[None, :, :, None]).astype(
        np.int64)
