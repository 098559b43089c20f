"""Evaluation of "dynamic-pde" clips (the decoder :data:`pdeanim.clip.DECODERS` maps the kind to).

Everything that does not depend on t is precomputed when a clip is loaded: the per-vertex space basis
(V, 3, 4) and, per knot, its per-vertex contribution P (S+1, V, 3), plus the item (curve, coordinate) of
every value. A frame at t is then: find the segment (pure Python), evaluate the time pair of the items of
that segment once per distinct mu (few in the integer-coded format) and compute positions = rest +
phi0 * P[s] + phi1 * P[s+1] per value (items on the natural spline: a weighted sum of four fields, two knots
and the spline's two tangents, precomputed per knot at load, with weights shared by the segment). Both steps
are one compiled pass each (numba: no
BLAS, so no caller meets BLAS threading, and no temporaries; the numpy path below stays as the fallback).
"""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np

try:
    from numba import njit

    COMPILED = True
except ImportError:  # pragma: no cover - numba is a pinned dependency; this keeps the numpy path usable
    COMPILED = False

from .. import container
from ..errors import ClipFormatError
from .bonelayer import BonePlayer, has_bones
from .clipformat import CoefficientData, TopologyData, decode_coefficients, decode_topology
from .families import MU_TRIG_MAX, SPACE_KINDS, space_basis
from .rigid import RigidTracks
from .spline import clamped_tangents, natural_tangents, spline_frame_weights
from .timefit import SIN_COEF

_ODD = 2.0 * np.arange(len(SIN_COEF)) + 1.0  # (P,) odd powers of the sine series


class DynamicClip:
    """A decoded dynamic-PDE clip implementing :class:`pdeanim.clip.Clip`."""

    kind = "dynamic-pde"

    def __init__(self, topo: TopologyData, coef: CoefficientData, lazy_segments: bool = False,
                 end_tangents: tuple[np.ndarray | None, np.ndarray | None] | None = None,
                 bone_end_tangents: np.ndarray | None = None):
        """``lazy_segments``: build each segment's time tables on its first use instead of at load (a block
        of curves evaluated at a few times, :mod:`pdeanim.model.clipblocks`). ``end_tangents``: the spline
        items' tangent coefficients (C, 3, 4) float64 at the first and last knot (None: that end's natural
        condition), which clamp the spline (a window of a streamable clip, docs/format.md §3.10);
        ``bone_end_tangents`` (2, B, 6) the same for the bone layer's spline channels."""
        self.topo, self.coef = topo, coef
        self._lazy = lazy_segments
        self.n_vertices = int(len(topo.rest))
        self.faces = np.asarray(topo.faces, np.int32)
        self.frame_times = np.asarray(coef.frame_times, np.float64)
        self.looping = bool(coef.looping)
        self.segment_t = np.asarray(coef.segment_t, np.float64)
        self._segment_list = [float(x) for x in self.segment_t]
        self._cid, _ = topo.curves.curve_of_vertex(self.n_vertices)
        if self.n_vertices and not (self._cid.min() >= 0 and self._cid.max() < topo.curves.n_curves):
            raise ClipFormatError("the topology's curves do not cover every vertex (corrupt topology)")
        fam = coef.family.astype(np.int64)
        self._mu = np.where(fam >= 2, -1.0, 1.0) * coef.m.astype(np.float64)  # (S, C, 3) signed
        spline = coef.spline_items().reshape(-1)
        self._cubic_items = [spline] * len(self._mu)  # per segment, the items on the spline (§3.5): all

        self._rigid = RigidTracks.from_arrays(coef.extra) if coef.motion == "rigid" else None
        self.bones = None if coef.bones is None else BonePlayer(coef.bones, topo.rest, self.looping,
                                                                 bone_end_tangents)
        if coef.motion == "displacement":
            self._base = topo.rest.astype(np.float32)
        elif self._rigid is not None:
            self._base = (topo.rest - self._rigid.centre0[self._cid]).astype(np.float32)
        else:
            self._base = np.zeros((self.n_vertices, 3), np.float32)
        self._base_flat = self._base.ravel()
        self._init_gather(self._precompute(fam[0] % 2))
        self._tangent_fields = None  # (S+1, V*3) float32 natural-spline tangents of the knot fields (§3.5)
        if spline.any() and (end_tangents is None or all(e is None for e in end_tangents)):
            self._tangent_fields = _spline_tangent_fields(self._knot_fields, self.segment_t)
        elif spline.any():
            ends = self._end_fields(fam[0] % 2, end_tangents)
            self._tangent_fields = _clamped_tangent_fields(self._knot_fields, self.segment_t, ends)

    def _init_gather(self, knot_fields: np.ndarray) -> None:
        """The flat (S+1, V * 3) knot fields and, per segment, the distinct time value of every value (its
        item's mu; uint16 where the segment has few, as the integer-coded format gives)."""
        self._knot_fields = np.ascontiguousarray(knot_fields.reshape(len(knot_fields), -1))  # (S+1, V*3)
        self._item_of = (np.asarray(self._cid, np.intp)[:, None] * 3 + np.arange(3)).ravel()  # (V*3,) item
        mu, cubic_items, item_of = self._mu, self._cubic_items, self._item_of

        def build(s: int) -> tuple[_SegmentTime, np.ndarray, np.ndarray | None]:  # holds no reference to self
            return _segment_tables(mu[s], cubic_items[s], item_of)

        if self._lazy:
            tables = _LazySegments(len(mu), build)
            self._time, self._value_code, self._cubic_values = (_Column(tables, k) for k in range(3))
            return
        built = [build(s) for s in range(len(mu))]
        self._time = [b[0] for b in built]
        self._value_code = [b[1] for b in built]
        self._cubic_values = [b[2] for b in built]

    def _vertex_basis(self, space_i: np.ndarray) -> np.ndarray:
        """(V, 3, 4) float64 space basis of every vertex and coordinate (§3.6)."""
        u = self.topo.u.astype(np.float64)  # (V, 3)
        D = self.coef.D.astype(np.float64)[self._cid]  # (V, 3)
        kind_v = space_i[self._cid]  # (V, 3)
        B = np.zeros((self.n_vertices, 3, 4))
        for i, kind in enumerate(SPACE_KINDS):
            sel = kind_v == i
            if np.any(sel):
                B[sel] = space_basis(u[sel][:, None], D[sel], kind)[:, 0, :]
        return B

    def _end_fields(self, space_i: np.ndarray, coefs: tuple[np.ndarray | None, np.ndarray | None]
                    ) -> list[np.ndarray | None]:
        """(V * 3,) float64 fields of per-item coefficients (C, 3, 4) (the end tangents of a window; None
        stays None), in float64 and not rounded (docs/format.md §3.10)."""
        B = self._vertex_basis(space_i)
        return [None if c is None else np.einsum("vwk,vwk->vw", B, np.asarray(c, np.float64)[self._cid]
                                                 ).reshape(-1) for c in coefs]

    def _precompute(self, space_i: np.ndarray) -> np.ndarray:
        """(S+1, V, 3) float32 per-vertex contribution of every knot."""
        B = self._vertex_basis(space_i)
        knots = self.coef.knots
        out = np.empty((len(knots), self.n_vertices, 3), np.float32)
        for s in range(len(knots)):  # one knot at a time keeps the peak memory at (V, 3, 4)
            out[s] = np.einsum("vwk,vwk->vw", B, knots[s].astype(np.float64)[self._cid])
        return out

    def _locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=np.float64)
        t = t - np.floor(t) if self.looping else np.clip(t, 0.0, 1.0)
        S = len(self.segment_t) - 1
        seg = np.clip(np.searchsorted(self.segment_t, t, side="right") - 1, 0, S - 1)
        t0, t1 = self.segment_t[seg], self.segment_t[seg + 1]
        tau = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
        return seg, tau, t

    def _locate_scalar(self, t: float) -> tuple[int, float, float]:
        """(segment, tau, wrapped t) of one time in pure Python; equals :meth:`_locate` on a 1-element
        array."""
        t = t - math.floor(t) if self.looping else min(max(t, 0.0), 1.0)
        knots = self._segment_list
        seg = min(max(bisect.bisect_right(knots, t) - 1, 0), len(knots) - 2)
        t0, t1 = knots[seg], knots[seg + 1]
        tau = min(max((t - t0) / (t1 - t0 if t1 > t0 else 1.0), 0.0), 1.0)
        return seg, tau, t

    def _frame(self, s: int, tau: float, out: np.ndarray | None = None, base: np.ndarray | None = None
               ) -> np.ndarray:
        """(V, 3) float32 positions (before any rigid motion) in segment s at local time tau; ``base``
        (V * 3,) float32 in place of the clip's (the skinned positions of a bone layer)."""
        if out is None:
            out = np.empty((self.n_vertices, 3), np.float32)
        base = self._base_flat if base is None else base
        flat, fields, code = out.reshape(-1), self._knot_fields, self._value_code[s]
        phi = self._time[s].pair_values(tau)  # (2, U) float32 of the segment's distinct values
        if self._cubic_values[s] is not None:
            return self._cubic_frame(s, tau, phi, out, base)
        if COMPILED:
            _combine(phi[0], phi[1], code, fields[s], fields[s + 1], base, flat)
            return out
        a, b = np.take(phi[0], code), np.take(phi[1], code)
        np.multiply(a, fields[s], out=a)  # phi0 * P[s]
        np.multiply(b, fields[s + 1], out=b)  # phi1 * P[s+1]
        np.add(a, b, out=flat)
        np.add(flat, base, out=flat)
        return out

    def _cubic_frame(self, s: int, tau: float, phi: np.ndarray, out: np.ndarray, base: np.ndarray
                     ) -> np.ndarray:
        """:meth:`_frame` of a segment with spline items: their values sum four fields, the tangents and
        knots at s and s+1 (§3.5)."""
        flat, fields, code = out.reshape(-1), self._knot_fields, self._value_code[s]
        w = spline_frame_weights(self._segment_list, s, tau)
        first, last = self._tangent_fields[s], self._tangent_fields[s + 1]
        w32 = np.array(w, np.float32)
        if COMPILED:
            _combine_cubic(phi[0], phi[1], code, phi.shape[1], w32[0], w32[1], w32[2], w32[3], first,
                           fields[s], fields[s + 1], last, base, flat)
            return out
        phi = np.concatenate([phi, np.zeros((2, 1), np.float32)], axis=1)  # the cubic code: pair unused
        a, b = np.take(phi[0], code), np.take(phi[1], code)
        np.add(a * fields[s] + b * fields[s + 1], base, out=flat)
        i = self._cubic_values[s]
        flat[i] = (((w32[0] * first[i] + w32[1] * fields[s][i]) + w32[2] * fields[s + 1][i])
                   + w32[3] * last[i]) + base[i]
        return out

    def evaluate(self, t: float | np.ndarray) -> np.ndarray:
        """Positions in the original vertex order: (V, 3) float32 for scalar t, (K, V, 3) for an array."""
        if (self._rigid is None and isinstance(t, (int, float, np.floating, np.integer))
                and math.isfinite(t)):
            s, tau, tw = self._locate_scalar(float(t))  # one frame: no per-call array bookkeeping
            return self._frame(s, tau, base=self._bone_base(np.array([tw]), 0))
        scalar = np.ndim(t) == 0
        seg, tau, tw = self._locate(np.atleast_1d(t))
        out = np.empty((len(seg), self.n_vertices, 3), np.float32)
        bases = None if self.bones is None else self.bones.positions(tw).reshape(len(tw), -1)
        for k, (s, x) in enumerate(zip(seg, tau, strict=True)):
            self._frame(int(s), float(x), out[k], None if bases is None else bases[k])
        if self._rigid is not None:
            R, c = self._rigid.at(tw)  # (K, C, 3, 3), (K, C, 3)
            out = (np.einsum("kvij,kvj->kvi", R[:, self._cid], out) + c[:, self._cid]).astype(np.float32)
        return out[0] if scalar else out

    def _bone_base(self, tw: np.ndarray, k: int) -> np.ndarray | None:
        """(V * 3,) float32 skinned positions of the bone layer at wrapped time tw[k] (None: no bones)."""
        return None if self.bones is None else self.bones.positions(tw[k:k + 1]).reshape(-1)

    def frame_t(self) -> np.ndarray:
        """(F,) normalised times of the source frames."""
        ft = self.frame_times
        span = ft[-1] - ft[0]
        return (ft - ft[0]) / span if span > 0 else np.zeros_like(ft)

    def info(self) -> dict[str, Any]:
        """JSON-able metadata: frames, segments, curves, motion, errors achieved."""
        bones = self.coef.bones
        return _info(self.n_vertices, int(len(self.frame_times)), int(len(self.segment_t) - 1),
                     self.topo.curves.n_curves, self.topo.param_mode, self.coef.header,
                     float(self.frame_times[-1] - self.frame_times[0]),
                     None if bones is None else bones.n_segments)


def _info(n_vertices: int, n_frames: int, n_segments: int, n_curves: int, param_mode: str,
          header: dict[str, Any], duration_s: float, bone_segments: int | None = None) -> dict[str, Any]:
    """The metadata of :meth:`DynamicClip.info` from its parts (``header``: the coefficients part's;
    ``bone_segments``: the bone layer's segments, None without one)."""
    return {
        "kind": DynamicClip.kind,
        "n_vertices": n_vertices,
        "n_frames": n_frames,
        "n_segments": n_segments,
        "n_curves": n_curves,
        "motion": str(header.get("motion")),
        "looping": bool(header.get("looping", False)),
        "param_mode": param_mode,
        "duration_s": duration_s,
        "errors": header.get("errors", {}),
        **{k: header[k] for k in ("gait", "travel") if isinstance(header.get(k), dict)},  # gait clips
        **({} if bone_segments is None else {"bones": {
            "n_bones": header.get("n_bones"), "influences": header.get("bone_influences"),
            "segments": bone_segments}}),
    }


def header_info(topology: bytes, coefficients: bytes) -> dict[str, Any]:
    """:meth:`DynamicClip.info` of a clip's two parts from their headers, array shapes and frame times alone:
    nothing whose size grows with segments x curves is decoded (the metadata route of a long clip)."""
    th, t_shapes = container.shapes(topology)
    ch, arrays = container.unpack(coefficients, names=("frame_times",))
    ft = arrays.get("frame_times")
    if ft is None or ft.ndim != 1 or len(ft) < 1 or "rest" not in t_shapes or "curve_lengths" not in t_shapes:
        raise ClipFormatError("a dynamic-pde clip needs frame_times, rest and curve_lengths arrays")
    S = ch.get("n_segments")
    if not isinstance(S, int) or isinstance(S, bool) or S < 1:
        raise ClipFormatError(f"coefficients header field 'n_segments' must be a positive integer, got {S!r}")
    ft = np.asarray(ft, np.float64)
    bone_segments = None
    if has_bones(ch):
        _, c_shapes = container.shapes(coefficients)
        if len(c_shapes.get("bone_segment_t", ())) != 1:
            raise ClipFormatError("coefficients with bones need a one-dimensional bone_segment_t array")
        bone_segments = int(c_shapes["bone_segment_t"][0]) - 1
    return _info(int(t_shapes["rest"][0]), int(len(ft)), S, int(t_shapes["curve_lengths"][0]),
                 str(th.get("param_mode", "chord")), ch, float(ft[-1] - ft[0]), bone_segments)


def _segment_tables(mu: np.ndarray, cubic: np.ndarray, item_of: np.ndarray
                    ) -> tuple[_SegmentTime, np.ndarray, np.ndarray | None]:
    """One segment's time pair (its items' signed mu (C, 3)), the code of every value's distinct time value,
    and its values on the spline (``cubic`` (C*3,) items, ``item_of`` (V*3,) the item of every value)."""
    seg = _SegmentTime(mu.ravel())
    code = np.where(cubic, seg.n_values, seg.code)  # cubic items: one more code, past the pair values
    small = seg.n_values < np.iinfo(np.uint16).max
    return (seg, np.ascontiguousarray(code[item_of], np.uint16 if small else np.int32),
            np.flatnonzero(cubic[item_of]) if cubic.any() else None)


class _LazySegments:
    """Per-segment tables built on a segment's first use."""

    def __init__(self, n: int, build: Any) -> None:
        self._items: list[Any] = [None] * n
        self._build = build

    def get(self, s: int) -> Any:
        item = self._items[s]
        if item is None:
            item = self._items[s] = self._build(s)
        return item


class _Column:
    """One of the per-segment tables (column k of :class:`_LazySegments`), indexed by segment."""

    def __init__(self, tables: _LazySegments, k: int) -> None:
        self._tables, self._k = tables, k

    def __getitem__(self, s: int) -> Any:
        return self._tables.get(s)[self._k]


class _SegmentTime:
    """Fast evaluation of the time pair of all items of one segment (precomputed constants).

    The pair depends on an item's signed mu alone, and clips store few distinct values per segment (the
    integer-coded format: 143-243 of 21k items on a 20k-vertex clip), so it is evaluated once per distinct
    value (``code`` maps items to them), grouped exp | trig | linear. Compiled: one pass writing float32
    (phi0, phi1) (trig: the sine series of :data:`timefit.SIN_COEF` by Horner's rule on m (1 - tau) and m tau,
    over sin m, as float64 sines are slow). The numpy path evaluates the same in one (2, U) float64 buffer
    (trig: one (2, P) @ (P, nt) product) and permutes it back with one ``take``.
    """

    def __init__(self, mu: np.ndarray):
        values, code = np.unique(np.asarray(mu, np.float64), return_inverse=True)
        self.n, self.code = len(mu), code.reshape(-1)
        exp, trig = np.flatnonzero(values > 1e-12), np.flatnonzero(values < -1e-12)
        lin = np.flatnonzero(np.abs(values) <= 1e-12)
        self.n_values = len(values)
        self.ne, self.nt = len(exp), len(trig)
        self.exp_items, self.trig_items, self.lin_items = exp, trig, lin
        me, mt = values[exp], np.minimum(-values[trig], MU_TRIG_MAX)  # the clip of time_pair
        self.me = np.ascontiguousarray(me)
        self.inv_exp = 1.0 / np.expm1(-2.0 * me)
        self.mt = np.ascontiguousarray(mt)
        self.inv_sin = 1.0 / np.sin(mt)
        if COMPILED:
            return
        self.position = np.argsort(np.concatenate([exp, trig, lin]), kind="stable")  # value -> grouped slot
        self.me2 = np.stack([me, me])  # (2, ne)
        # sin(m t) = sum_k (c_k m^(2k+1)) t^(2k+1) (timefit.sin_table): the m side, over sin m, precomputed
        powers = mt[None, :] ** _ODD[:, None] * SIN_COEF[:, None]  # (P, nt)
        self.trig_table = np.ascontiguousarray(powers / np.sin(mt))

    def pair(self, tau: float) -> np.ndarray:
        """(2, N) float32 (phi0, phi1) in item order at local time tau; equals :func:`time_pair` to
        rounding."""
        return np.take(self.pair_values(tau), self.code, axis=1)

    def pair_values(self, tau: float) -> np.ndarray:
        """(2, U) float32 (phi0, phi1) of the distinct values at local time tau."""
        if COMPILED:
            out = np.empty((2, self.n_values), np.float32)
            _pair(float(tau), self.me, self.inv_exp, self.exp_items, self.mt, self.inv_sin, self.trig_items,
                  self.lin_items, SIN_COEF, out[0], out[1])
            return out
        g = np.empty((2, self.n_values))
        ne, nt = self.ne, self.nt
        if ne:
            # phi0 = e^{-m tau} expm1(-2m (1 - tau)) / expm1(-2m); phi1 = e^{m (tau - 1)} expm1(-2m tau) / ...
            ge = g[:, :ne]
            np.multiply(self.me2, np.array([[-tau], [tau - 1.0]]), out=ge)
            np.exp(ge, out=ge)
            b = np.multiply(self.me2, np.array([[-2.0 * (1.0 - tau)], [-2.0 * tau]]))
            np.expm1(b, out=b)
            np.multiply(ge, b, out=ge)
            np.multiply(ge, self.inv_exp, out=ge)
        if nt:  # (phi0, phi1) = ((1 - tau)^(2k+1), tau^(2k+1)) @ table: one small product, no float64 sine
            g[:, ne:ne + nt] = np.power(np.array([[1.0 - tau], [tau]]), _ODD) @ self.trig_table
        g[0, ne + nt:], g[1, ne + nt:] = 1.0 - tau, tau
        # position is a permutation of range(U) (an argsort), never out of range; "wrap": no buffering
        return np.take(g.astype(np.float32), self.position, axis=1, mode="wrap")


def _pair(tau: float, me: np.ndarray, inv_exp: np.ndarray, exp_items: np.ndarray, mt: np.ndarray,
          inv_sin: np.ndarray, trig_items: np.ndarray, lin_items: np.ndarray, coef: np.ndarray,
          phi0: np.ndarray, phi1: np.ndarray) -> None:
    """Compiled time pair at tau of one segment's distinct values into float32 phi0, phi1."""
    s = 1.0 - tau
    for j in range(me.shape[0]):
        m, i = me[j], exp_items[j]
        phi0[i] = np.float32(math.exp(m * -tau) * math.expm1(m * (-2.0 * s)) * inv_exp[j])
        phi1[i] = np.float32(math.exp(m * (tau - 1.0)) * math.expm1(m * (-2.0 * tau)) * inv_exp[j])
    top = coef.shape[0] - 1
    for j in range(mt.shape[0]):
        m, i = mt[j], trig_items[j]
        y0, y1 = m * s, m * tau
        z0, z1 = y0 * y0, y1 * y1
        a0, a1 = coef[top], coef[top]
        for k in range(top - 1, -1, -1):  # sin y = y * sum_k c_k (y^2)^k
            a0 = a0 * z0 + coef[k]
            a1 = a1 * z1 + coef[k]
        phi0[i] = np.float32(y0 * a0 * inv_sin[j])
        phi1[i] = np.float32(y1 * a1 * inv_sin[j])
    for j in range(lin_items.shape[0]):
        i = lin_items[j]
        phi0[i], phi1[i] = np.float32(s), np.float32(tau)


def _combine(phi0: np.ndarray, phi1: np.ndarray, code: np.ndarray, p0: np.ndarray, p1: np.ndarray,
             base: np.ndarray, out: np.ndarray) -> None:
    """Compiled (phi0 * P[s] + phi1 * P[s+1]) + base per value (phi of its distinct time value ``code``),
    in float32 as the numpy path rounds it."""
    for v in range(out.shape[0]):
        i = code[v]
        out[v] = (phi0[i] * p0[v] + phi1[i] * p1[v]) + base[v]


def _combine_cubic(phi0: np.ndarray, phi1: np.ndarray, code: np.ndarray, cubic: int, w0: np.float32,
                   w1: np.float32, w2: np.float32, w3: np.float32, pl: np.ndarray, p0: np.ndarray,
                   p1: np.ndarray, ph: np.ndarray, base: np.ndarray, out: np.ndarray) -> None:
    """Compiled :func:`_combine` where values of code ``cubic`` sum four fields (tangent, knot, knot, tangent)
    with float32 weights w0..w3 (docs/format.md §3.5), in the float32 order of the numpy path."""
    for v in range(out.shape[0]):
        i = code[v]
        if i == cubic:
            out[v] = (((w0 * pl[v] + w1 * p0[v]) + w2 * p1[v]) + w3 * ph[v]) + base[v]
        else:
            out[v] = (phi0[i] * p0[v] + phi1[i] * p1[v]) + base[v]


if COMPILED:
    _combine_cubic = njit(cache=True, nogil=True, boundscheck=False)(_combine_cubic)
    _pair = njit(cache=True, nogil=True, boundscheck=False)(_pair)
    _combine = njit(cache=True, nogil=True, boundscheck=False)(_combine)


SPLINE_CHUNK = 1 << 16
"""Values per block of the natural-spline tangent solve at load (bounds its float64 scratch)."""


def _spline_tangent_fields(fields: np.ndarray, segment_t: np.ndarray) -> np.ndarray:
    """(S+1, V*3) float32 natural-spline tangents of the float32 knot fields, solved in float64 (§3.5)."""
    out = np.empty_like(fields)
    for a in range(0, fields.shape[1], SPLINE_CHUNK):
        out[:, a:a + SPLINE_CHUNK] = natural_tangents(fields[:, a:a + SPLINE_CHUNK], segment_t)
    return out


def _clamped_tangent_fields(fields: np.ndarray, segment_t: np.ndarray, ends: list[np.ndarray | None]
                            ) -> np.ndarray:
    """(S+1, V*3) float32 tangents of the float32 knot fields with the given float64 end tangent fields
    (V*3,) (None: natural end), solved in float64 (docs/format.md §3.10)."""
    out = np.empty_like(fields)
    for a in range(0, fields.shape[1], SPLINE_CHUNK):
        cols = slice(a, a + SPLINE_CHUNK)
        first, last = (None if e is None else e[cols] for e in ends)
        out[:, cols] = clamped_tangents(fields[:, cols], segment_t, first, last)
    return out


def clip_from_parts(topo_header: dict[str, Any], topo_arrays: dict[str, np.ndarray],
                    coef_header: dict[str, Any], coef_arrays: dict[str, np.ndarray]) -> DynamicClip:
    """Loader for kind "dynamic-pde" (see :func:`pdeanim.clip.load_clip`)."""
    topo = decode_topology(topo_header, topo_arrays)
    coef = decode_coefficients(coef_header, coef_arrays, topo.curves.n_curves)
    return DynamicClip(topo, coef)
