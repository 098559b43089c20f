"""Evaluation of "dynamic-pde" clips: the loader registered in :data:`pdeanim.clip.LOADERS`.

Everything that does not depend on t is precomputed when a clip is loaded: the per-vertex space basis
(V, 3, 4) and, per knot, its per-vertex contribution P (S+1, V, 3). A frame at t is then: find the
segment, evaluate the time pair of every curve+coordinate, gather it per vertex, and
positions = rest + phi0 * P[s] + phi1 * P[s+1] (a few multiply-adds per vertex).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from .clipformat import CoefficientData, TopologyData, decode_coefficients, decode_topology
from .families import SPACE_KINDS, space_basis
from .rigid import RigidTracks


class DynamicClip:
    """A decoded dynamic-PDE clip implementing :class:`pdeanim.clip.Clip`."""

    kind = "dynamic-pde"

    def __init__(self, topo: TopologyData, coef: CoefficientData):
        self.topo, self.coef = topo, coef
        self.n_vertices = int(len(topo.rest))
        self.faces = np.asarray(topo.faces, np.int32)
        self.frame_times = np.asarray(coef.frame_times, np.float64)
        self.looping = bool(coef.looping)
        self.segment_t = np.asarray(coef.segment_t, np.float64)
        self._cid, _ = topo.curves.curve_of_vertex(self.n_vertices)
        fam = coef.family.astype(np.int64)
        self._mu = np.where(fam >= 2, -1.0, 1.0) * coef.m.astype(np.float64)  # (S, C, 3) signed
        self._time = [_SegmentTime(mu.ravel()) for mu in self._mu]
        self._knot_fields = self._precompute(fam[0] % 2).reshape(len(self._mu) + 1, -1)  # (S+1, V*3)
        self._local = threading.local()
        self._rigid = RigidTracks.from_arrays(coef.extra) if coef.motion == "rigid" else None
        if coef.motion == "displacement":
            self._base = topo.rest.astype(np.float32)
        elif self._rigid is not None:
            self._base = (topo.rest - self._rigid.centre0[self._cid]).astype(np.float32)
        else:
            self._base = np.zeros((self.n_vertices, 3), np.float32)
        self._base_flat = self._base.ravel()
        item_of = (self._cid[:, None] * 3 + np.arange(3)).ravel()  # (V*3,) item of every value
        self._gather = [st.position[item_of].astype(np.intp) for st in self._time]  # per segment

    def _precompute(self, space_i: np.ndarray) -> np.ndarray:
        """(S+1, V, 3) float32 per-vertex contribution of every knot."""
        u = self.topo.u.astype(np.float64)  # (V, 3)
        D = self.coef.D.astype(np.float64)[self._cid]  # (V, 3)
        kind_v = space_i[self._cid]  # (V, 3)
        B = np.zeros((self.n_vertices, 3, 4))
        for i, kind in enumerate(SPACE_KINDS):
            sel = kind_v == i
            if np.any(sel):
                B[sel] = space_basis(u[sel][:, None], D[sel], kind)[:, 0, :]
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

    def _frame(self, s: int, tau: float) -> np.ndarray:
        phi0, phi1 = self._time[s].pair(tau)  # (C*3,) each
        bufs = getattr(self._local, "bufs", None)
        if bufs is None:  # per-thread scratch (avoids fresh large allocations on every frame)
            bufs = self._local.bufs = (np.empty(self.n_vertices * 3, np.float32),
                                       np.empty(self.n_vertices * 3, np.float32))
        b0, b1 = bufs
        np.take(phi0, self._gather[s], out=b0)
        np.multiply(b0, self._knot_fields[s], out=b0)
        np.take(phi1, self._gather[s], out=b1)
        np.multiply(b1, self._knot_fields[s + 1], out=b1)
        np.add(b0, b1, out=b0)
        return np.add(b0, self._base_flat).reshape(self.n_vertices, 3)

    def evaluate(self, t: float | np.ndarray) -> np.ndarray:
        """Positions in the original vertex order: (V, 3) float32 for scalar t, (K, V, 3) for an array."""
        scalar = np.ndim(t) == 0
        seg, tau, tw = self._locate(np.atleast_1d(t))
        out = np.stack([self._frame(int(s), float(x)) for s, x in zip(seg, tau, strict=True)])
        if self._rigid is not None:
            R, c = self._rigid.at(tw)  # (K, C, 3, 3), (K, C, 3)
            out = (np.einsum("kvij,kvj->kvi", R[:, self._cid], out) + c[:, self._cid]).astype(np.float32)
        return out[0] if scalar else out

    def frame_t(self) -> np.ndarray:
        """(F,) normalised times of the source frames."""
        ft = self.frame_times
        span = ft[-1] - ft[0]
        return (ft - ft[0]) / span if span > 0 else np.zeros_like(ft)

    def info(self) -> dict[str, Any]:
        """JSON-able metadata: frames, segments, curves, motion, errors achieved."""
        h = self.coef.header
        return {"kind": self.kind, "n_vertices": self.n_vertices, "n_frames": int(len(self.frame_times)),
                "n_segments": int(len(self.segment_t) - 1), "n_curves": self.topo.curves.n_curves,
                "motion": self.coef.motion, "looping": self.looping, "param_mode": self.topo.param_mode,
                "duration_s": float(self.frame_times[-1] - self.frame_times[0]), "errors": h.get("errors", {})}


class _SegmentTime:
    """Fast evaluation of the time pair of all items of one segment (precomputed denominators).

    Items are grouped exp | trig | linear; ``position[item]`` is where an item's value lands in that order.
    """

    def __init__(self, mu: np.ndarray):
        exp, trig = np.flatnonzero(mu > 1e-12), np.flatnonzero(mu < -1e-12)
        lin = np.flatnonzero(np.abs(mu) <= 1e-12)
        self.position = np.argsort(np.concatenate([exp, trig, lin]), kind="stable")
        self.m_exp, self.m_trig, self.n_lin = mu[exp], -mu[trig], len(lin)
        self.inv_exp = 1.0 / np.expm1(-2.0 * self.m_exp)
        self.inv_trig = 1.0 / np.sin(self.m_trig)

    def pair(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """(phi0, phi1) float32 in grouped order at local time tau; equals :func:`time_pair` to rounding."""
        me, mt, lin = self.m_exp, self.m_trig, np.ones(self.n_lin)
        p1 = np.concatenate([np.exp(me * (tau - 1.0)) * np.expm1(-2.0 * me * tau) * self.inv_exp,
                             np.sin(mt * tau) * self.inv_trig, tau * lin])
        p0 = np.concatenate([np.exp(-me * tau) * np.expm1(-2.0 * me * (1.0 - tau)) * self.inv_exp,
                             np.sin(mt * (1.0 - tau)) * self.inv_trig, (1.0 - tau) * lin])
        return p0.astype(np.float32), p1.astype(np.float32)


def clip_from_parts(topo_header: dict[str, Any], topo_arrays: dict[str, np.ndarray],
                    coef_header: dict[str, Any], coef_arrays: dict[str, np.ndarray]) -> DynamicClip:
    """Loader for kind "dynamic-pde" (see :func:`pdeanim.clip.load_clip`)."""
    topo = decode_topology(topo_header, topo_arrays)
    coef = decode_coefficients(coef_header, coef_arrays, topo.curves.n_curves)
    return DynamicClip(topo, coef)
