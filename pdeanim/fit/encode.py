"""A fitted model as the two parts of a clip (at a given rounding), and back to an evaluable clip: the fit
measures what it stores."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .. import container
from ..clipparts import ClipParts
from ..container import ZSTD_LEVEL
from ..curveset import CurveSet
from ..model.clipformat import (
    TIME_PDE,
    TIME_SPLINE,
    CoefficientData,
    TopologyData,
    coefficient_arrays,
    decode_coefficients,
    decode_topology,
    encode_coefficients,
    encode_topology,
    topology_arrays,
)
from ..model.clipmodel import DynamicClip, clip_from_parts
from ..model.fitcore import SpaceStage, TimeStage
from ..model.knotbasis import TrackSpectrum, track_spectrum
from ..poses import Poses
from .options import FitOptions
from .problem import Problem


@dataclass
class Quantisation:
    """How the stored clip is rounded: per-coordinate tolerance (rest; knots unless knot_rms), the RMS budget
    of the knots' rounding, the most it may move a vertex coordinate (None: the format's defaults), and how
    many times each curve's knot steps are halved beyond that (refine (C, 3), where the max bound asks it)."""

    tolerance: float | None = None
    knot_rms: float | None = None
    knot_cap: float | None = None
    refine: np.ndarray | None = None
    rank: int | None = None  # the knots on that many shared time tracks (0: plain tracks; None: the smallest;
    # -r: on the leading r of a windowed fit's shared weights, SpaceStage.shared_weights)

    def finer(self) -> Quantisation:
        """Half the rounding error."""
        def half(x: float | None) -> float | None:
            return None if x is None else x / 2
        return replace(self, tolerance=half(self.tolerance), knot_rms=half(self.knot_rms),
                       knot_cap=half(self.knot_cap))

    def coarser(self, factor: float) -> Quantisation:
        """``factor`` x the knots' rounding (the cap no further than what a max target leaves)."""
        assert self.knot_rms is not None and self.knot_cap is not None
        return replace(self, knot_rms=factor * self.knot_rms, knot_cap=factor * self.knot_cap)

    def refined(self, curves: np.ndarray, n_curves: int) -> Quantisation:
        """The same rounding with the knot steps of ``curves`` (indices) halved once more."""
        refine = np.zeros((n_curves, 3), np.int64) if self.refine is None else self.refine.copy()
        refine[curves] += 1
        return replace(self, refine=refine)


def coefficient_data(space: SpaceStage, fitted: TimeStage, options: FitOptions, times: np.ndarray,
                     errors: dict) -> CoefficientData:
    """The unrounded coefficients of a fit, in the clip layout (segment, curve, coordinate)."""
    K = space.b.shape[0]
    C, S = K // 3, fitted.segm.n_segments
    mu = fitted.mu.reshape(C, 3, S)
    family = (2 * (mu < 0) + space.proj.kind.reshape(C, 3)[:, :, None]).astype(np.uint8)
    knots = fitted.knots.reshape(C, 3, S + 1, 4)
    time_model = np.full((C, 3), TIME_PDE, np.uint8)
    if fitted.spline is not None:
        time_model[fitted.spline.reshape(C, 3)] = TIME_SPLINE
    return CoefficientData(fitted.segm.segment_t, times, np.moveaxis(family, 2, 0),
                           np.moveaxis(np.abs(mu), 2, 0), space.proj.D.reshape(C, 3),
                           np.moveaxis(knots, 2, 0), options.motion, options.loop, {"errors": errors},
                           time_model=time_model, shared=space.shared_weights)


def encode(p: Problem, curves: CurveSet, space: SpaceStage, fitted: TimeStage, options: FitOptions,
           poses: Poses, errors: dict | None = None, quant: Quantisation | None = None,
           level: int = ZSTD_LEVEL) -> ClipParts:
    """Both parts of the clip of a fit, rounded as ``quant`` says, compressed at zstd ``level``."""
    quant = quant or Quantisation()
    u = p.u_per_vertex()
    topology = encode_topology(curves, u, poses.faces, p.rest, options.param_mode, quant.tolerance, level)
    coef = coefficient_data(space, fitted, options, np.asarray(poses.times, np.float64), errors or {})
    if p.rigid is not None:
        coef.extra = p.rigid.arrays()
    return ClipParts(topology, encode_coefficients(topology, coef, quant.tolerance, quant.knot_rms,
                                                   quant.knot_cap, level, True,
                                                   _spectrum(fitted, curves, u, coef), quant.refine,
                                                   quant.rank))


def _spectrum(fitted: TimeStage, curves: CurveSet, u: np.ndarray, coef: CoefficientData
              ) -> TrackSpectrum | None:
    """The knot tracks' spectrum of a fit (the same for every rounding of its knots: computed once)."""
    if "spectrum" not in fitted.cache:
        fitted.cache["spectrum"] = track_spectrum(curves, u.astype(np.float32), coef.family,
                                                  np.asarray(coef.m, np.float32), coef.D, coef.knots)
    return fitted.cache["spectrum"]


def stored_clip(p: Problem, curves: CurveSet, space: SpaceStage, fitted: TimeStage, options: FitOptions,
                poses: Poses, quant: Quantisation) -> DynamicClip:
    """The clip a reader decodes from :func:`encode` with the knots on ``quant.rank`` shared tracks (None or
    0: plain tracks), built from the unpacked arrays (nothing compressed): what the rate control measures
    each rounding on."""
    topo, header, arrays = unpacked_coefficients(p, curves, space, fitted, options, poses, quant)
    return DynamicClip(topo, decode_coefficients(header, arrays, topo.curves.n_curves))


def unpacked_coefficients(p: Problem, curves: CurveSet, space: SpaceStage, fitted: TimeStage,
                          options: FitOptions, poses: Poses, quant: Quantisation
                          ) -> tuple[TopologyData, dict, dict[str, np.ndarray]]:
    """(decoded topology, coefficients header, arrays) of :func:`encode` with the knots on ``quant.rank``
    shared tracks (None or 0: plain tracks), neither part compressed (knot differences of order 1): the same
    decoded knots and codes, without the trial compressions."""
    u = p.u_per_vertex()
    header, arrays = topology_arrays(curves, u, poses.faces, p.rest, options.param_mode, quant.tolerance)
    topo = decode_topology(header, arrays)
    coef = coefficient_data(space, fitted, options, np.asarray(poses.times, np.float64), {})
    if p.rigid is not None:
        coef.extra = p.rigid.arrays()
    spectrum = _spectrum(fitted, curves, u, coef) if quant.rank else None
    header, arrays = coefficient_arrays("", topo, coef, quant.tolerance, quant.knot_rms, quant.knot_cap,
                                        spectrum=spectrum, choose=False, knot_refine=quant.refine,
                                        knot_rank=quant.rank or 0)
    return topo, header, arrays


def decode(parts: ClipParts) -> DynamicClip:
    """The evaluable clip of encoded parts."""
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    return clip_from_parts(th, ta, ch, ca)
