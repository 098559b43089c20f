"""The bone layer of clip format 1.1 (feature "bones", docs/format.md §3.9): B rigid transforms over time and
linear-blend skinning weights (at most 4 influences per vertex); the dynamic-PDE curves are a residual on top.

Each bone has six channels (rotation vector, translation) fitted in time with the clip's time models (the
paper's time pair per segment, or the natural spline, chosen per channel as the curves choose) on the bone
tracks' own segments, chosen error-driven, then rounded to power-of-two steps. Errors are vertex distances,
bounded per frame from weighted moments of the rest pose around each pivot (no (F, V) arrays in the fit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

try:
    from numba import njit

    COMPILED = True
except ImportError:  # pragma: no cover - numba is a pinned dependency; the numpy path stays usable
    COMPILED = False

from .. import container
from ..errors import ClipFormatError, ParameterError
from . import quantise
from .adaptive import Targets, _split_count, _splits
from .families import time_pair
from .rigid import rodrigues
from .segments import Segmentation, normalised_times, uniform_segmentation
from .spline import clamped_tangents, hermite_basis, natural_tangents, prefer_spline
from .timefit import fit_tracks_spline, predict, solve_knots

BONES_FEATURE = "bones"
"""The feature name a part with a bone layer lists in its header's ``required``."""
BONES_VERSION = "1.1"
"""The format version of a part (and CLIP file) with a bone layer."""
MAX_INFLUENCES = 4
CHANNELS = 6
"""Channels of a bone: rotation vector (0..2, radians) and translation (3..5)."""
TIME_PDE, TIME_SPLINE = 0, 1
FIT_SHARE, KNOT_SHARE, WEIGHT_SHARE = 0.8, 0.4, 0.3
"""Shares of the bone layer's RMS budget: the time fit, the rounding of the knots, the rounding of the weights
(in quadrature: 0.94 of the budget)."""
PRUNE_SHARE = 0.3
"""Share of the bone layer's RMS budget by which dropping a vertex's weakest influences may move it."""
WEIGHT_BITS = (4, 16)
"""Range of the weights' quantisation: levels of 1 / (2^n - 1), n chosen from the budget (format: 1..16)."""
HALVINGS = 8
"""Most halvings of every knot step when the rounded tracks miss their budget (spline weights above 1)."""
WEIGHT_SAMPLE_FRAMES = 8
MU_MANTISSA_BITS = 4
"""Significant bits kept of a bone channel's time constant (truncated towards 0, so caps still hold; the
knots are solved again for the kept constants): a few distinct float32 patterns compress to a fraction of the
golden-section refinement's values (CesiumMan, 16 segments x 19 bones x 6 channels: 2.7 KB of bone_m)."""
MAX_BONE_CODE = 2**23
"""Largest magnitude of a bone knot code: p * h (h a power of two) then has at most 24 significant bits, so
float32(p * h) is exact and a knot is off its value by the rounding to the step alone."""


@dataclass(frozen=True)
class BoneMotion:
    """What a decomposition (SSDR, a glTF skin) produces, per source frame: x -> R (x - pivot) + pivot + T."""

    pivot: np.ndarray  # (B, 3) float64 rest-pose pivots
    index: np.ndarray  # (V, K) int64 bone of each influence, original vertex order
    weight: np.ndarray  # (V, K) float64, rows sum to 1
    rotvec: np.ndarray  # (F, B, 3) float64 rotation vectors (made continuous over frames by encode_bones)
    translation: np.ndarray  # (F, B, 3) float64

    @property
    def n_bones(self) -> int:
        return int(len(self.pivot))


@dataclass(frozen=True)
class EncodedBones:
    """A quantised bone layer, as stored (docs/format.md §3.9): knots are float32(codes * step)."""

    segment_t: np.ndarray  # (Sb+1,) float64 strictly increasing from 0 to 1
    pivot: np.ndarray  # (B, 3) float32
    index: np.ndarray  # (V, K) uint16
    weight_q: np.ndarray  # (V, K) uint16 quantised weights, each row summing to 2^weight_bits - 1
    time_model: np.ndarray  # (B, 6) uint8: TIME_PDE or TIME_SPLINE
    mu: np.ndarray  # (Sb, B, 6) float32 signed time constants (0 on spline channels)
    step: np.ndarray  # (B, 6) float32 power-of-two knot steps
    codes: np.ndarray  # (Sb+1, B, 6) int64 knot codes
    knot_differences: int = 1  # order of the zigzag differences of the stored tracks
    weight_bits: int = 16  # the weights are q / (2^weight_bits - 1); the last column is implied when stored
    report: dict[str, Any] = field(default_factory=dict, compare=False)  # what the encoder did (not stored)

    @property
    def n_bones(self) -> int:
        return int(len(self.pivot))

    @property
    def n_influences(self) -> int:
        return int(self.index.shape[1])

    @property
    def n_segments(self) -> int:
        return int(len(self.segment_t) - 1)

    def knots(self) -> np.ndarray:
        """(Sb+1, B, 6) float32 knot values float32(p * h)."""
        return quantise.dequantise(self.codes, self.step[None])

    def weights(self) -> np.ndarray:
        """(V, K) float64 weights q / (2^weight_bits - 1)."""
        return self.weight_q.astype(np.float64) / float(2**self.weight_bits - 1)


# ---------------------------------------------------------------- evaluation (readers and the fit)

class BoneTracks:
    """The time tracks of an encoded bone layer (§3.9 steps 1-2): knots in float64, their spline tangents."""

    def __init__(self, enc: EncodedBones, looping: bool = False, end_tangents: np.ndarray | None = None):
        """``end_tangents`` (2, B, 6) float64: the spline channels' tangents at the first and last knot,
        clamping the spline (a window of a streamable clip, docs/format.md §3.10); None: natural ends."""
        self.enc, self.looping = enc, bool(looping)
        self.seg_t = np.asarray(enc.segment_t, np.float64)
        B = enc.n_bones
        self.P = enc.knots().astype(np.float64).reshape(len(self.seg_t), B * CHANNELS)
        self.spline = (np.asarray(enc.time_model) == TIME_SPLINE).reshape(-1)
        self.tangents = None
        if self.spline.any() and end_tangents is None:
            self.tangents = natural_tangents(self.P, self.seg_t)
        elif self.spline.any():
            ends = np.asarray(end_tangents, np.float64).reshape(2, B * CHANNELS)
            self.tangents = clamped_tangents(self.P, self.seg_t, ends[0], ends[1])
        self.mu = np.asarray(enc.mu, np.float32).astype(np.float64).reshape(-1, B * CHANNELS)

    def wrap(self, t: np.ndarray) -> np.ndarray:
        """Normalised times wrapped (looping) or clamped into [0, 1] (§2)."""
        t = np.asarray(t, np.float64)
        return t - np.floor(t) if self.looping else np.clip(t, 0.0, 1.0)

    def channels(self, t: np.ndarray) -> np.ndarray:
        """(n, B, 6) float64 channel values at normalised times t (n,) (§3.9 step 1)."""
        tw = self.wrap(np.atleast_1d(t))
        seg_t, Sb = self.seg_t, len(self.seg_t) - 1
        s = np.clip(np.searchsorted(seg_t, tw, side="right") - 1, 0, Sb - 1)
        t0, t1 = seg_t[s], seg_t[s + 1]
        tau = np.clip((tw - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
        P0, P1 = self.P[s], self.P[s + 1]  # (n, B*6)
        phi = time_pair(np.broadcast_to(tau[:, None], P0.shape), self.mu[s])
        out = phi[..., 0] * P0 + phi[..., 1] * P1
        if self.tangents is not None:
            h00, h01, h10, h11 = (h[:, None] for h in hermite_basis(tau))
            delta = (t1 - t0)[:, None]
            cubic = h00 * P0 + h01 * P1 + delta * (h10 * self.tangents[s] + h11 * self.tangents[s + 1])
            out = np.where(self.spline[None], cubic, out)
        return out.reshape(len(tw), self.enc.n_bones, CHANNELS)

    def transforms(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R (n, B, 3, 3), T (n, B, 3)) float64 of every bone at normalised times t (n,) (§3.9 step 2)."""
        v = self.channels(t)
        return rodrigues(v[..., :3]), v[..., 3:]


class BonePlayer:
    """Evaluates an encoded bone layer on a rest pose, in the order docs/format.md §3.9 gives; the tracks,
    the weights and the rest pose in float64 are prepared once."""

    def __init__(self, enc: EncodedBones, rest: np.ndarray, looping: bool = False,
                 end_tangents: np.ndarray | None = None):
        self.enc, self.tracks = enc, BoneTracks(enc, looping, end_tangents)
        self.rest = np.asarray(rest, np.float32).astype(np.float64)
        if self.rest.shape != (len(enc.index), 3):
            raise ClipFormatError(f"the bone layer has {len(enc.index)} vertices, the rest pose "
                                  f"{self.rest.shape[0]}")
        self.pivot = np.asarray(enc.pivot, np.float32).astype(np.float64)
        self.index = np.asarray(enc.index, np.int64)
        self.weight = enc.weights()

    def positions(self, t: np.ndarray) -> np.ndarray:
        """(n, V, 3) float32 skinned positions at normalised times t (n,) (§3.9 step 3)."""
        R, T = self.tracks.transforms(t)
        out = np.empty((len(R), len(self.rest), 3), np.float32)
        for f in range(len(R)):
            if COMPILED:  # one pass over the vertices, no (V, 3, 3) gathers: the frame route's hot path
                _blend_into(R[f], T[f], self.pivot, self.index, self.weight, self.rest, out[f])
            else:
                out[f] = blend(R[f], T[f], self.pivot, self.index, self.weight, self.rest)
        return out


def blend(R: np.ndarray, T: np.ndarray, pivot: np.ndarray, index: np.ndarray, weight: np.ndarray,
          rest: np.ndarray) -> np.ndarray:
    """(V, 3) float64 linear-blend skinning of one frame in the spec's order: for k = 0..K-1,
    acc += w[v, k] * ((R_b (rest_v - c_b) + c_b) + T_b), R_b y summed as (R0 y0 + R1 y1) + R2 y2."""
    acc = np.zeros_like(rest, dtype=np.float64)
    for k in range(index.shape[1]):
        b = index[:, k]
        y = rest - pivot[b]  # (V, 3)
        Rb = R[b]  # (V, 3, 3)
        ry = (Rb[:, :, 0] * y[:, 0:1] + Rb[:, :, 1] * y[:, 1:2]) + Rb[:, :, 2] * y[:, 2:3]
        acc += weight[:, k:k + 1] * ((ry + pivot[b]) + T[b])
    return acc


def _blend_into(R: np.ndarray, T: np.ndarray, pivot: np.ndarray, index: np.ndarray, weight: np.ndarray,
                rest: np.ndarray, out: np.ndarray) -> None:
    """Compiled :func:`blend` rounded to float32 into ``out`` (V, 3), in the same float64 order."""
    for v in range(rest.shape[0]):
        a0 = a1 = a2 = 0.0
        for k in range(index.shape[1]):
            b, w = index[v, k], weight[v, k]
            y0, y1, y2 = rest[v, 0] - pivot[b, 0], rest[v, 1] - pivot[b, 1], rest[v, 2] - pivot[b, 2]
            r0 = (R[b, 0, 0] * y0 + R[b, 0, 1] * y1) + R[b, 0, 2] * y2
            r1 = (R[b, 1, 0] * y0 + R[b, 1, 1] * y1) + R[b, 1, 2] * y2
            r2 = (R[b, 2, 0] * y0 + R[b, 2, 1] * y1) + R[b, 2, 2] * y2
            a0 += w * ((r0 + pivot[b, 0]) + T[b, 0])
            a1 += w * ((r1 + pivot[b, 1]) + T[b, 1])
            a2 += w * ((r2 + pivot[b, 2]) + T[b, 2])
        out[v, 0], out[v, 1], out[v, 2] = np.float32(a0), np.float32(a1), np.float32(a2)


if COMPILED:
    _blend_into = njit(cache=True, nogil=True, boundscheck=False)(_blend_into)


def skinned_positions(enc: EncodedBones, rest: np.ndarray, t: np.ndarray, looping: bool = False
                      ) -> np.ndarray:
    """(n, V, 3) float32 base positions of the decoded bone layer at normalised times t (n,), exactly as a
    reader evaluates them."""
    return BonePlayer(enc, rest, looping).positions(np.atleast_1d(np.asarray(t, np.float64)))


def skin(motion: BoneMotion, rest: np.ndarray) -> np.ndarray:
    """(F, V, 3) float64 linear-blend skinning of the per-frame transforms of ``motion`` on ``rest``."""
    rest = np.asarray(rest, np.float64)
    R = rodrigues(np.asarray(motion.rotvec, np.float64))
    T = np.asarray(motion.translation, np.float64)
    pivot, index = np.asarray(motion.pivot, np.float64), np.asarray(motion.index, np.int64)
    weight = np.asarray(motion.weight, np.float64)
    return np.stack([blend(R[f], T[f], pivot, index, weight, rest) for f in range(len(R))]) if len(R) else \
        np.zeros((0,) + rest.shape)


# ---------------------------------------------------------------- encoding (the fit side)

def unwrap_rotvec(r: np.ndarray) -> np.ndarray:
    """(F, B, 3) rotation vectors on the branch nearest the previous frame's (the same rotations, no jumps of
    2 pi along the axis): each (theta + 2 pi k) n with k nearest (n . r_prev - theta) / 2 pi."""
    r = np.array(r, np.float64)
    for f in range(1, len(r)):
        prev, cur = r[f - 1], r[f]
        theta = np.linalg.norm(cur, axis=-1)
        prev_norm = np.linalg.norm(prev, axis=-1)
        tiny = theta < 1e-12  # identity: any axis; take the previous one
        axis = np.where(tiny[:, None], prev / np.where(prev_norm > 0, prev_norm, 1.0)[:, None],
                        cur / np.where(tiny, 1.0, theta)[:, None])
        k = np.rint((np.einsum("bi,bi->b", axis, prev) - theta) / (2.0 * np.pi))
        r[f] = (theta + 2.0 * np.pi * k)[:, None] * axis
    return r


@dataclass(frozen=True)
class _Moments:
    """Weighted moments of the rest pose around each bone's pivot: sum w, sum w y, sum w y y^T (y = x - c)."""

    m0: np.ndarray  # (B,)
    m1: np.ndarray  # (B, 3)
    m2: np.ndarray  # (B, 3, 3)
    n_vertices: int

    @staticmethod
    def of(rest: np.ndarray, pivot: np.ndarray, index: np.ndarray, weight: np.ndarray) -> _Moments:
        B = len(pivot)
        y = np.asarray(rest, np.float64)[:, None, :] - pivot[index]  # (V, K, 3)
        idx, w = index.ravel(), weight.ravel()
        yf = y.reshape(-1, 3)
        m0 = np.bincount(idx, w, B)
        m1 = np.stack([np.bincount(idx, w * yf[:, i], B) for i in range(3)], axis=1)
        m2 = np.stack([np.stack([np.bincount(idx, w * yf[:, i] * yf[:, j], B) for j in range(3)], 1)
                       for i in range(3)], 1)
        return _Moments(m0, m1, m2, len(rest))

    def frame_error_sq(self, R_fit: np.ndarray, T_fit: np.ndarray, R: np.ndarray, T: np.ndarray
                       ) -> np.ndarray:
        """(F,) bound on the mean squared vertex distance between two sets of transforms (F, B, ...): by
        convexity of the blend, |sum_b w e_b|^2 <= sum_b w |e_b|^2, and sum_v w |A y + d|^2 is exact in the
        moments."""
        A, d = R_fit - R, T_fit - T
        e = self.m0 * np.einsum("fbi,fbi->fb", d, d)
        e += 2.0 * np.einsum("fbi,fbij,bj->fb", d, A, self.m1)
        e += np.einsum("fbij,bjk,fbik->fb", A, self.m2, A)
        return np.maximum(e, 0.0).sum(axis=1) / max(self.n_vertices, 1)

    def levers(self) -> np.ndarray:
        """(B,) RMS distance of each bone's weighted vertices from its pivot (0 for a bone without any)."""
        tr = np.trace(self.m2, axis1=1, axis2=2)
        return np.sqrt(np.where(self.m0 > 0, tr / np.where(self.m0 > 0, self.m0, 1.0), 0.0))


def _check_motion(motion: BoneMotion, frame_times: np.ndarray, rest: np.ndarray) -> None:
    """ParameterError unless the shapes agree and the numbers are usable."""
    B = motion.n_bones
    V, K = np.shape(motion.index)
    F = len(frame_times)
    if not 1 <= B <= np.iinfo(np.uint16).max + 1 or not 1 <= K <= MAX_INFLUENCES:
        raise ParameterError(f"a bone layer needs 1..65536 bones and 1..{MAX_INFLUENCES} influences, "
                             f"got B={B}, K={K}")
    if np.shape(motion.pivot) != (B, 3) or np.shape(motion.weight) != (V, K) or np.shape(rest) != (V, 3):
        raise ParameterError("bone pivots (B, 3), weights (V, K) and rest (V, 3) disagree in shape")
    if np.shape(motion.rotvec) != (F, B, 3) or np.shape(motion.translation) != (F, B, 3):
        raise ParameterError(f"bone rotations and translations must be ({F}, {B}, 3)")
    if F < 1 or (F > 1 and not np.all(np.diff(frame_times) > 0)):
        raise ParameterError("bone tracks need frame times that strictly increase")
    index = np.asarray(motion.index)
    if index.size and (index.min() < 0 or index.max() >= B):
        raise ParameterError("a bone index lies outside the bones")
    w = np.asarray(motion.weight, np.float64)
    if np.any(w < 0) or not np.allclose(w.sum(axis=1), 1.0, atol=1e-6):
        raise ParameterError("bone weights must be non-negative and sum to 1 per vertex")
    for name in ("pivot", "rotvec", "translation"):
        if not np.all(np.isfinite(getattr(motion, name))):
            raise ParameterError(f"bone {name} holds non-finite values")


def encode_bones(motion: BoneMotion, frame_times: np.ndarray, target_rms: float, rest: np.ndarray,
                 looping: bool = False) -> EncodedBones:
    """The bone layer of ``motion`` fitted in time and quantised: at most ``target_rms`` (absolute RMS vertex
    distance, fit and rounding together) from skin(motion, rest) at the frames where the segments allow.
    Segments are added where frames miss the fit's share of the budget; each channel takes the natural
    spline or the paper's time pair (per segment constants) as the curves choose them (spline.prefer_spline,
    timefit.fit_tracks_spline). ``looping`` clips are fitted the same way: t = 1 wraps to 0, so the last knot
    is only approached, and a motion that loops meets its first pose there in rotation (a bone that turns a
    full circle per cycle too, which periodic rotation-vector knots could not hold); it is recorded in the
    report."""
    frame_times = np.asarray(frame_times, np.float64)
    _check_motion(motion, frame_times, rest)
    if not target_rms > 0:
        raise ParameterError(f"the bone layer's target RMS must be positive, got {target_rms}")
    pivot = np.asarray(motion.pivot, np.float32).astype(np.float64)  # what readers get
    rest32 = np.asarray(rest, np.float32).astype(np.float64)
    rotvec = unwrap_rotvec(motion.rotvec)
    values = np.concatenate([rotvec, np.asarray(motion.translation, np.float64)], axis=2)  # (F, B, 6)
    weight_q, weight_bits, weight_rms = _quantise_weights(motion, rest32, pivot, target_rms)
    index, weight_q = sorted_influences(np.asarray(motion.index, np.int64), weight_q)
    weight = weight_q / float(2**weight_bits - 1)
    moments = _Moments.of(rest32, pivot, index, weight)
    R, T = rodrigues(rotvec), values[..., 3:]
    segm, z, mu, spline, fit_rms = _fit_segments(values, frame_times, moments, R, T, FIT_SHARE * target_rms)
    step, codes, rms = _quantise_knots(z, mu, spline, segm, moments, R, T, target_rms)
    B = motion.n_bones
    _, order = quantise.encode_knot_tracks(codes)
    report = {"segments": segm.n_segments, "spline_channels": int(spline.sum()), "fit_rms_bound": fit_rms,
              "rms_bound": rms, "weight_bits": weight_bits, "weight_rms_estimate": weight_rms,
              "target_rms": float(target_rms), "met": bool(math.hypot(rms, weight_rms) <= target_rms),
              "looping": bool(looping)}
    return EncodedBones(segment_t=_segment_times(segm), pivot=pivot.astype(np.float32),
                        index=index.astype(np.uint16), weight_q=weight_q.astype(np.uint16),
                        time_model=spline.reshape(B, CHANNELS).astype(np.uint8),
                        mu=np.moveaxis(mu.reshape(B, CHANNELS, -1), -1, 0).astype(np.float32),
                        step=step.reshape(B, CHANNELS), codes=codes, knot_differences=order,
                        weight_bits=weight_bits, report=report)


def _segment_times(segm: Segmentation) -> np.ndarray:
    """(Sb+1,) float64 boundaries of the bone segments, exactly 0 and 1 at the ends."""
    seg_t = np.array(segm.segment_t, np.float64)
    seg_t[0], seg_t[-1] = 0.0, 1.0
    return seg_t


def _fit_segments(values: np.ndarray, frame_times: np.ndarray, moments: _Moments, R: np.ndarray,
                  T: np.ndarray, goal: float
                  ) -> tuple[Segmentation, np.ndarray, np.ndarray, np.ndarray, float]:
    """(segmentation, knots (B*6, Sb+1), constants (B*6, Sb), spline (B*6,) bool, RMS bound): segments split
    at the worst frames until the time fit's vertex error bound meets ``goal`` or every frame is a knot."""
    F, B, _ = values.shape
    b = np.moveaxis(values.reshape(F, B * CHANNELS), 0, 1)[:, :, None]  # (B*6, F, 1) tracks
    if F == 1:  # a still: one linear segment holding the frame at both ends
        z = np.repeat(b[:, :, 0], 2, axis=1)
        still = Segmentation(np.array([0, 0]), np.zeros(1))
        return still, z, np.zeros((len(b), 1)), np.zeros(len(b), bool), 0.0
    t = normalised_times(frame_times)
    candidates = prefer_spline(b, t)
    segm = uniform_segmentation(frame_times, 1)
    while True:
        z, mu, spline = fit_tracks_spline(b, segm, candidates)
        mu = coarse_mu(mu)
        pair = ~spline
        if pair.any():
            z[pair] = solve_knots(b[pair], segm, mu[pair])
        fitted = np.moveaxis(predict(z, segm, mu, spline)[:, :, 0], 0, 1).reshape(F, B, CHANNELS)
        err = moments.frame_error_sq(rodrigues(fitted[..., :3]), fitted[..., 3:], R, T)
        rms = float(np.sqrt(err.mean()))
        if rms <= goal or segm.n_segments >= F - 1:
            break
        n_split = max(1, _split_count(segm.n_segments, rms, rms, Targets(rms=goal)))
        new = _splits(segm, np.sqrt(err) / goal, n_split)
        if new.n_segments == segm.n_segments:
            break
        segm = new
    return segm, z[:, :, 0], mu, spline, rms


def coarse_mu(mu: np.ndarray, bits: int = MU_MANTISSA_BITS) -> np.ndarray:
    """Time constants with ``bits`` significant bits, truncated towards 0 (float32-exact)."""
    mu = np.asarray(mu, np.float64)
    mantissa, exponent = np.frexp(np.abs(mu))  # |mu| = mantissa * 2^exponent, mantissa in [0.5, 1)
    kept = np.floor(mantissa * 2.0**bits) / 2.0**bits
    return np.sign(mu) * np.ldexp(kept, exponent)


def _quantise_knots(z: np.ndarray, mu: np.ndarray, spline: np.ndarray, segm: Segmentation, moments: _Moments,
                    R: np.ndarray, T: np.ndarray, target: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(steps (B*6,) float32, codes (Sb+1, B, 6) int64, RMS bound of the rounded tracks): power-of-two steps
    from the rounding's share of the budget (rotations through each bone's lever arm), halved while the
    decoded tracks miss the budget."""
    K = len(z)
    B = K // CHANNELS
    e = KNOT_SHARE * target / math.sqrt(2.0)  # 3 rotation + 3 translation components, RMS h / sqrt(12) each
    lever = np.repeat(moments.levers()[:, None], CHANNELS, axis=1)
    lever[:, 3:] = 1.0
    with np.errstate(divide="ignore"):
        tol = np.where(lever.ravel() > 0, e / lever.ravel(), np.inf)
    biggest = np.abs(z).max(axis=1)
    seg_t = _segment_times(segm)
    enc_base = dict(segment_t=seg_t, pivot=np.zeros((B, 3), np.float32),
                    index=np.zeros((1, 1), np.uint16), weight_q=np.ones((1, 1), np.uint16),
                    time_model=spline.reshape(B, CHANNELS).astype(np.uint8),
                    mu=np.moveaxis(mu.reshape(B, CHANNELS, -1), -1, 0).astype(np.float32))
    frames_t = segm.t if len(segm.t) > 1 else np.zeros(1)
    for halving in range(HALVINGS + 1):
        step = _steps(tol * 2.0 ** -halving, biggest)
        codes = np.moveaxis(np.rint(z / step.astype(np.float64)[:, None]).astype(np.int64), 1, 0)
        codes = codes.reshape(-1, B, CHANNELS)
        enc = EncodedBones(step=step.reshape(B, CHANNELS), codes=codes, **enc_base)
        v = BoneTracks(enc).channels(frames_t)
        rms = float(np.sqrt(moments.frame_error_sq(rodrigues(v[..., :3]), v[..., 3:], R, T).mean()))
        if rms <= math.hypot(FIT_SHARE, KNOT_SHARE) * target:
            break
    return step, codes, rms


def _steps(tol: np.ndarray, biggest: np.ndarray) -> np.ndarray:
    """(n,) float32 power-of-two steps whose half is at most ``tol`` (inf: the coarsest useful step, a bone
    that moves no vertex), coarse enough that every code stays within MAX_BONE_CODE."""
    top = 2.0 ** np.ceil(np.log2(np.maximum(biggest, 2.0**-100)))
    step = np.minimum(2.0 * tol, top)
    step = np.maximum(step, biggest / MAX_BONE_CODE)
    step = np.clip(step, np.finfo(np.float32).tiny, 2.0**100)
    return (2.0 ** np.floor(np.log2(step))).astype(np.float32)


def _quantise_weights(motion: BoneMotion, rest: np.ndarray, pivot: np.ndarray, target: float
                      ) -> tuple[np.ndarray, int, float]:
    """(q (V, K) int64, bits, RMS estimate): the influences that move their vertex least (weight times the
    distance of the influence's position from the blend, summed, within PRUNE_SHARE of the budget per
    vertex; never a vertex's largest) dropped, the others renormalised and rounded to n-bit levels, n the
    fewest whose expected RMS vertex error (each weight's rounding, uniform, times the spread of the
    influences' positions over a few frames) is within the weights' share of the budget. Dropped influences
    store as zero weights (and the previous slot's bone), which compress to almost nothing."""
    w = np.array(motion.weight, np.float64)
    index = np.asarray(motion.index, np.int64)
    F = len(motion.rotvec)
    frames = np.unique(np.linspace(0, F - 1, min(F, WEIGHT_SAMPLE_FRAMES)).round().astype(np.int64))
    R = rodrigues(np.asarray(motion.rotvec, np.float64)[frames])
    T = np.asarray(motion.translation, np.float64)[frames]
    y = rest[:, None, :] - pivot[index]  # (V, K, 3)
    positions = [np.einsum("vkij,vkj->vki", R[f][index], y) + pivot[index] + T[f][index]
                 for f in range(len(frames))]
    if PRUNE_SHARE > 0 and index.shape[1] > 1 and len(rest):
        dist = np.zeros(w.shape)
        for p in positions:
            mean = np.einsum("vk,vki->vi", w, p)
            dist = np.maximum(dist, np.linalg.norm(p - mean[:, None], axis=-1))
        cost = w * dist
        cost[np.arange(len(w)), np.argmax(w, axis=1)] = np.inf  # a vertex keeps its largest influence
        order = np.argsort(cost, axis=1, kind="stable")
        running = np.cumsum(np.take_along_axis(cost, order, 1), axis=1)
        drop = np.zeros(w.shape, bool)
        np.put_along_axis(drop, order, running <= PRUNE_SHARE * target, 1)
        w = np.where(drop, 0.0, w)
        w /= w.sum(axis=1, keepdims=True)
    spread = 0.0
    for p in positions:
        mean = np.einsum("vk,vki->vi", w, p)
        spread += float(((w > 0)[..., None] * (p - mean[:, None]) ** 2).sum()) / max(len(rest), 1)
    spread /= max(len(frames), 1)
    for bits in range(WEIGHT_BITS[0], WEIGHT_BITS[1] + 1):
        scale = 2**bits - 1
        rms = math.sqrt(spread / 12.0) / scale
        if rms <= WEIGHT_SHARE * target or bits == WEIGHT_BITS[1]:
            break
    return weight_levels(w, scale), bits, rms


def weight_levels(w: np.ndarray, scale: int) -> np.ndarray:
    """(V, K) int64 integers q, each row summing to ``scale``, nearest w * scale (largest remainders)."""
    exact = w * scale
    q = np.floor(exact).astype(np.int64)
    short = scale - q.sum(axis=1)  # 0..K-1 units still to hand out per row
    rank = np.argsort(np.argsort(-(exact - q), axis=1, kind="stable"), axis=1, kind="stable")
    return q + (rank < short[:, None])


def sorted_influences(index: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index, q) (V, K) with a vertex's repeated bone merged, influences by ascending bone, zero weights
    last with the previous slot's bone: the order writers store (it compresses best)."""
    index, q = np.array(index, np.int64), np.array(q, np.int64)
    K = index.shape[1]
    for k in range(1, K):
        for j in range(k):
            same = (index[:, k] == index[:, j]) & (q[:, j] > 0)
            q[same, j] += q[same, k]
            q[same, k] = 0
    order = np.argsort(np.where(q > 0, index, np.iinfo(np.int64).max), axis=1, kind="stable")
    index, q = np.take_along_axis(index, order, 1), np.take_along_axis(q, order, 1)
    for k in range(1, K):
        index[:, k] = np.where(q[:, k] > 0, index[:, k], index[:, k - 1])
    return index, q


# ---------------------------------------------------------------- the stored form

def bones_header_arrays(enc: EncodedBones) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header keys, arrays) the bone layer adds to a coefficients part (§3.9), ``format_version`` and
    ``required`` included."""
    header = {"format_version": BONES_VERSION, "required": [BONES_FEATURE], "n_bones": enc.n_bones,
              "bone_influences": enc.n_influences, "bone_knot_differences": int(enc.knot_differences),
              "bone_weight_bits": int(enc.weight_bits)}
    arrays = {
        "bone_segment_t": np.asarray(enc.segment_t, np.float64),
        "bone_pivot": np.asarray(enc.pivot, np.float32),
        "bone_index": np.asarray(enc.index, np.uint16),
        "bone_weight": np.ascontiguousarray(np.asarray(enc.weight_q)[:, :-1], np.uint16),  # last implied
        "bone_time_model": np.asarray(enc.time_model, np.uint8),
        "bone_m": np.asarray(enc.mu, np.float32),
        "bone_step": np.asarray(enc.step, np.float32),
        "bone_knots": quantise.knot_tracks(enc.codes, enc.knot_differences),
    }
    return header, arrays


def has_bones(header: dict[str, Any]) -> bool:
    """Whether a part's header declares a bone layer (``required`` lists "bones")."""
    required = header.get("required", [])
    return isinstance(required, list) and BONES_FEATURE in required


def _int_key(header: dict[str, Any], key: str, lo: int, hi: int) -> int:
    value = header.get(key)
    if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
        raise ClipFormatError(f"bone layer header key {key!r} must be an integer in {lo}..{hi}, "
                              f"got {value!r}")
    return value


def _array(arrays: dict[str, np.ndarray], name: str, shape: tuple[int | None, ...], dtype: str) -> np.ndarray:
    """A bone array checked for presence, dtype, shape and (floats) finiteness."""
    if name not in arrays:
        raise ClipFormatError(f"the bone layer has no {name!r} array")
    a = arrays[name]
    if a.dtype.str.replace("|", "<") != dtype:
        raise ClipFormatError(f"bone array {name!r} has dtype {a.dtype.str}, expected {dtype}")
    if a.ndim != len(shape) or any(w is not None and h != w for h, w in zip(a.shape, shape, strict=True)):
        raise ClipFormatError(f"bone array {name!r} has shape {a.shape}, expected {shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ClipFormatError(f"bone array {name!r} has non-finite values")
    return a


def decode_bones(header: dict[str, Any], arrays: dict[str, np.ndarray], n_vertices: int | None = None
                 ) -> EncodedBones:
    """The validated bone layer of a coefficients part (§3.9); raises ClipFormatError."""
    if header.get("kind", "dynamic-pde") != "dynamic-pde" or header.get("motion") != "displacement":
        raise ClipFormatError(f"a bone layer needs kind 'dynamic-pde' and motion 'displacement', got "
                              f"{header.get('kind')!r} / {header.get('motion')!r}")
    B = _int_key(header, "n_bones", 1, np.iinfo(np.uint16).max + 1)
    K = _int_key(header, "bone_influences", 1, MAX_INFLUENCES)
    order = _int_key(header, "bone_knot_differences", 1, 2)
    bits = _int_key(header, "bone_weight_bits", 1, 16)
    seg_t = _array(arrays, "bone_segment_t", (None,), "<f8")
    Sb = len(seg_t) - 1
    if Sb < 1 or seg_t[0] != 0.0 or seg_t[-1] != 1.0 or np.any(np.diff(seg_t) <= 0):
        raise ClipFormatError("bone_segment_t must increase strictly from 0 to 1 with at least one segment")
    pivot = _array(arrays, "bone_pivot", (B, 3), "<f4")
    index = _array(arrays, "bone_index", (n_vertices, K), "<u2")
    stored = _array(arrays, "bone_weight", (len(index), K - 1), "<u2").astype(np.int64)
    if index.size and int(index.max()) >= B:
        raise ClipFormatError(f"a bone_index is not below n_bones ({B})")
    last = (2**bits - 1) - stored.sum(axis=1)
    if np.any(last < 0):
        raise ClipFormatError(f"a vertex's stored bone weights sum above 2^bone_weight_bits - 1 "
                              f"({2**bits - 1})")
    weight = np.concatenate([stored, last[:, None]], axis=1)
    time_model = _array(arrays, "bone_time_model", (B, CHANNELS), "<u1")
    if time_model.size and time_model.max() > TIME_SPLINE:
        raise ClipFormatError("bone_time_model must be 0 (paper pair) or 1 (natural spline)")
    mu = _array(arrays, "bone_m", (Sb, B, CHANNELS), "<f4")
    if np.any(mu <= -np.pi):
        raise ClipFormatError("bone trig time constants must be above -pi")
    if np.any((time_model == TIME_SPLINE)[None] & (mu != 0)):
        raise ClipFormatError("bone channels on the natural spline must have time constant 0")
    step = _array(arrays, "bone_step", (B, CHANNELS), "<f4")
    if np.any(step <= 0):
        raise ClipFormatError("bone knot steps must be positive")
    tracks = _array(arrays, "bone_knots", (B, CHANNELS, Sb + 1), "<u4")
    codes = quantise.decode_knot_tracks(tracks, order)
    enc = EncodedBones(np.array(seg_t), np.array(pivot), np.array(index), weight.astype(np.uint16),
                       np.array(time_model), np.array(mu), np.array(step), codes, order, bits)
    with np.errstate(over="ignore"):  # a float32 overflow is what this check reports
        finite = np.all(np.isfinite(enc.knots()))
    if not finite:
        raise ClipFormatError("bone knots decode to non-finite values")
    return enc


def add_bone_layer(header: dict[str, Any], arrays: dict[str, np.ndarray], enc: EncodedBones) -> None:
    """Add the bone layer's keys and arrays to a coefficients part's (header, arrays) in place: format 1.1,
    "bones" added to ``required``."""
    keys, bone_arrays = bones_header_arrays(enc)
    required = sorted(set(header.get("required", [])) | set(keys.pop("required")))
    header.update(keys, required=required)
    arrays.update(bone_arrays)


def repack_with_bone_layer(coefficients: bytes, enc: EncodedBones, level: int = container.ZSTD_LEVEL
                           ) -> bytes:
    """The coefficients part ``coefficients`` (kind "dynamic-pde", motion "displacement") repacked with the
    bone layer added, every array at its smallest encoding: its curves become the residual on the skinned
    rest pose, their values unchanged (the fit keeps the curves' encodings:
    :func:`pdeanim.fit.bonefit.append_bone_layer`)."""
    header, arrays = container.unpack(coefficients)
    if header.get("kind") != "dynamic-pde" or header.get("motion") != "displacement":
        raise ParameterError("a bone layer goes on a dynamic-PDE clip with motion 'displacement'")
    arrays = dict(arrays)
    add_bone_layer(header, arrays, enc)
    return container.pack(header, arrays, {name: container.SMALLEST for name in arrays}, level)
