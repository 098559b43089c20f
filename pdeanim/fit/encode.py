"""A fitted model as the two parts of a clip (at a given rounding), and back to an evaluable clip: the fit
measures what it stores."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import container
from ..clipparts import ClipParts
from ..container import ZSTD_LEVEL
from ..curveset import CurveSet
from ..model.clipformat import TIME_PDE, TIME_SPLINE, CoefficientData, encode_coefficients, encode_topology
from ..model.clipmodel import DynamicClip, clip_from_parts
from ..model.fitcore import SpaceStage, TimeStage
from ..model.knotbasis import track_spectrum
from ..poses import Poses
from .options import FitOptions
from .problem import Problem


@dataclass
class Quantisation:
    """How the stored clip is rounded: per-coordinate tolerance (rest; knots unless knot_rms), the RMS budget
    of the knots' rounding and the most it may move a vertex coordinate (None: the format's defaults)."""

    tolerance: float | None = None
    knot_rms: float | None = None
    knot_cap: float | None = None
    cap_limit: float = np.inf

    def finer(self) -> Quantisation:
        """Half the rounding error."""
        def half(x: float | None) -> float | None:
            return None if x is None else x / 2
        return Quantisation(half(self.tolerance), half(self.knot_rms), half(self.knot_cap), self.cap_limit)

    def coarser(self, factor: float) -> Quantisation:
        """``factor`` x the knots' rounding (the cap no further than what a max target leaves)."""
        assert self.knot_rms is not None and self.knot_cap is not None
        return Quantisation(self.tolerance, factor * self.knot_rms,
                            min(factor * self.knot_cap, self.cap_limit), self.cap_limit)


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
                           time_model=time_model)


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
    if "spectrum" not in fitted.cache:  # the same for every rounding of these knots: computed once
        fitted.cache["spectrum"] = track_spectrum(curves, u.astype(np.float32), coef.family,
                                                  np.asarray(coef.m, np.float32), coef.D, coef.knots)
    return ClipParts(topology, encode_coefficients(topology, coef, quant.tolerance, quant.knot_rms,
                                                   quant.knot_cap, level, spectrum=fitted.cache["spectrum"]))


def decode(parts: ClipParts) -> DynamicClip:
    """The evaluable clip of encoded parts."""
    th, ta = container.unpack(parts.topology)
    ch, ca = container.unpack(parts.coefficients)
    return clip_from_parts(th, ta, ch, ca)
