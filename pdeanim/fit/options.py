"""What a fit is asked for (:class:`FitOptions`, the user's options: the CLI flags and a fit job's JSON) and
how its stages trade size against error (:class:`FitTolerances`, the library's constants in one place, echoed
in every fit report)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..model.adaptive import Targets
from ..model.parameterisation import PARAM_MODES
from ..model.segments import DEFAULT_MAX_SEGMENTS

MOTIONS = ("displacement", "absolute", "rigid")
TIME_MODELS = ("auto", "pde", "spline")
"""``time_model`` choices: "auto" (per item, the natural spline where it predicts and fits the motion as well
as the paper's time pairs, else the paper's; the default), "pde" (the paper's time solution alone: families
with a constant m per segment, Eq. 5-8) or "spline" (every moving item of an open clip on the spline)."""
DEFAULT_TARGET_REL_RMS = 3e-3
MAX_BONES = 1024


@dataclass
class FitOptions:
    """What to fit and how well. Give error targets or a fixed segment count (not both); none = rel RMS 3e-3.

    target_rms / target_max : absolute per-vertex distance; target_rel_rms / target_rel_max : relative to
    the first frame's bounding-box diagonal. param_mode "chord" | "paper"; motion "displacement" |
    "absolute" | "rigid" (per-curve rigid tracks + residual in the curve's frame); loop: periodic knots (last
    frame flows into the first); max_segments caps the adaptivity (reaching it is reported, never silent).
    best_effort: a missed target is not an error (the CLI exits 0, a fit job succeeds with the best clip).
    time_model: see TIME_MODELS. bones: a bone layer under the curves (format 1.1): 0 none, N at most N
    bones fitted by a skinning decomposition, "auto" the bone count (0 included) whose clip is smallest; a
    skinned glTF input keeps its own skeleton instead (pdeanim.fit.bonefit).
    """

    target_rms: float | None = None
    target_rel_rms: float | None = None
    target_max: float | None = None
    target_rel_max: float | None = None
    segments: int | None = None
    param_mode: str = "chord"
    motion: str = "displacement"
    loop: bool = False
    max_segments: int = DEFAULT_MAX_SEGMENTS
    curve_points: int = 10
    best_effort: bool = False
    time_model: str = "auto"
    bones: int | str = 0

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> FitOptions:
        """Raise ParameterError on a bad value; returns self."""
        for name in ("target_rms", "target_rel_rms", "target_max", "target_rel_max"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int | float) and not isinstance(v, bool)
                                      and np.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be a positive number, got {v!r}")
        if self.segments is not None and not (
            isinstance(self.segments, int) and not isinstance(self.segments, bool) and self.segments >= 1
        ):
            raise ParameterError(f"segments must be an integer >= 1, got {self.segments!r}")
        if self.segments is not None and self.has_targets:
            raise ParameterError("give either a fixed segment count or error targets, not both")
        for name, allowed in (("param_mode", PARAM_MODES), ("motion", MOTIONS), ("time_model", TIME_MODELS)):
            if getattr(self, name) not in allowed:
                raise ParameterError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")
        for name in ("loop", "best_effort"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if self.bones != "auto" and not (isinstance(self.bones, int) and not isinstance(self.bones, bool)
                                         and 0 <= self.bones <= MAX_BONES):
            raise ParameterError(f"bones must be 'auto' or an integer in 0..{MAX_BONES}, got {self.bones!r}")
        if self.bones not in (0, "auto") and (self.motion != "displacement" or self.segments is not None):
            raise ParameterError("a bone layer needs motion 'displacement' and error targets (not a fixed "
                                 "segment count)")
        for name in ("max_segments", "curve_points"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 4096):
                raise ParameterError(f"{name} must be an integer in 1..4096, got {v!r}")
        return self

    @property
    def has_targets(self) -> bool:
        """Whether any error target is set."""
        return any(getattr(self, n) is not None for n in ("target_rms", "target_rel_rms", "target_max",
                                                             "target_rel_max"))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitOptions:
        """Options from a JSON-like dict; unknown keys or bad values raise ParameterError."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ParameterError(f"unknown fit option(s): {', '.join(unknown)}")
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (round-trips through from_dict)."""
        return asdict(self)

    def targets(self, diagonal: float) -> Targets:
        """Absolute targets (the tighter of absolute and relative where both are given)."""
        def pick(a: float | None, rel: float | None) -> float | None:
            """The tighter of an absolute and a relative target (None if neither)."""
            vals = [v for v in (a, None if rel is None else rel * diagonal) if v is not None]
            return min(vals) if vals else None
        rel_rms = self.target_rel_rms
        if not self.has_targets and self.segments is None:
            rel_rms = DEFAULT_TARGET_REL_RMS
        return Targets(pick(self.target_rms, rel_rms), pick(self.target_max, self.target_rel_max))


@dataclass(frozen=True)
class FitTolerances:
    """The constants by which a fit trades bytes against error, in one place (echoed as ``tolerances`` in
    every fit report). The figures in the comments were measured on the benchmark sequences; see
    docs/compression.md."""

    quant_share: float = 0.1
    """The rest pose (and, for max targets, the knots) are rounded by at most this share of the fit's tightest
    target per coordinate."""
    quant_budget: float = 0.8
    """With an RMS target only, the knots' rounding may take this share of what the fit leaves of the target
    (target^2 - fit rms^2, less the rest pose's share)."""
    knot_cap: float = 2.0
    """With an RMS budget for the knots' rounding, no vertex coordinate moves by more than this times it."""
    quant_retries: int = 10
    """Roundings tried at most after the first while the rounding is searched."""
    quant_fill: float = 0.85
    """The knots' rounding grows while the stored clip's RMS stays below this share of an RMS target."""
    quant_aim: float = 0.93
    """Each growth aims the stored clip's RMS at this share of the target: the rounding's share of the mean
    square error is taken as proportional to the knots' budget squared ..."""
    growth_min: float = 1.2
    growth_max: float = 4.0
    """... and the budget grows by a factor between these per step."""
    bisect_until: float = 1.05
    """When a grown rounding misses the target, the budget is bisected (geometric mean) between it and the
    last one that met it while they differ by more than this factor (and retries remain)."""
    soft_max_ratio: float | None = 3.0
    """An RMS target alone also asks, softly, that no vertex be off by more than this times it: a curve on
    which the knots' rounding takes a vertex past it gets finer steps (where the unrounded fit was within it),
    and of two candidate fits the one within it is kept. Never reported as a missed target. None: no soft
    bound."""
    skin_max_ratio: float | None = 1.0
    """A skinned glTF fitted on its own skeleton: the soft max bound is this times the RMS target (at most
    soft_max_ratio). The source is that skeleton's skinning, so the bone layer reaches any vertex with a few
    more bits of joint track where the curves would pay for every outlier; and a vertex off by 3x the target
    moves texture edges where a viewer sees them (the Look of issue 32: CesiumMan at 3e-3, three.js's own
    skinning as reference, 2.50% of the model's pixels off by > 40 levels with 3, 0.34% with 1, for 3.7%
    more coefficient bytes). None: soft_max_ratio."""
    skin_rd_slope: float | None = 8.0
    """... and its bone layer alone is encoded finer than the coarsest within the bounds, and of its clips
    that meet the targets the one kept, by least bytes x max error^(1 / this): a finer encoding is taken where
    it cuts the worst vertex's error by more than its byte growth to this power (2x lower for at most 9%
    more bytes). A quantiser's own slope is 3-6 (one more bit a value halves the error); joint tracks and
    weights step in coarser jumps (the Fox: 2x lower for 0.7% more bone-layer bytes). 6 and 8 chose the same
    on the creature, CesiumMan and the Fox. None: the smallest clip, the coarsest bone layer."""
    dense_fit: bool = True
    """Besides the error-driven search, fit a knot at every frame (or max_segments evenly spaced ones) and
    keep the smaller stored clip that meets the targets: a dense fit is far more accurate, which leaves most
    of the target to the knots' rounding, and its smooth knot tracks code small (elephant-gallop at 3e-3:
    35 segments 659 KB, 47 segments 429 KB; samba: 28 segments 688 KB, 174 segments 551 KB, both with a 4x
    lower max error; horse-collapse keeps its 5 segments for 52 frames)."""
    window_fit_values: int = 4_000_000
    """Inputs of more frame-vertex values than this are fitted in windows of frames, each window's segments
    chosen as a one-piece fit chooses them (:mod:`pdeanim.fit.windowed`: memory bounded by a window, not by
    the frames), where the options allow."""
    window_values: int = 4_194_304
    """Frame-vertex values per window of frames in a windowed fit (a window's float64 arrays take about 8
    bytes per value each)."""
    knot_basis: bool = True
    """Whether the knots may go on a shared time basis (format §3.4) where that is smaller. In a windowed fit
    the clip then has one knot step per item (the format's per-window knot steps need knot_rank 0)."""
    window_shared_weights: bool = True
    """In a windowed fit with knot_basis, every window may put its knots on one set of weights per clip (the
    principal shapes of the frames the curves are chosen on; stored once), not only on a basis of its own
    (AnimatedMorphSphere at 3e-3 in 2 and 8 windows: 1.16x and 1.51x the one-piece clip with a basis per
    window, 1.00x and 0.98x with the shared weights)."""
    window_quant_fill: float = 0.93
    """In a windowed fit each window's rounding grows while its RMS stays below this share of an RMS target
    (quant_fill of a one-piece fit): windows cannot trade error between them, so each lands closer to the
    target (samba in 4 windows at 3e-3: 476 KB at 0.85, 455 KB at 0.93, as one piece 437 KB)."""
    window_search_values: int = 2_000_000
    """In a windowed fit, a window of more frame-vertex values than this skips the error-driven segment
    search and stores the dense candidate (a knot at every frame, the one-piece rate control and shared knot
    basis): searching as well made windows 1.5-2.9x slower for the same bytes on pdance, elephant-gallop
    and horse-collapse, and on long inputs the dense candidate is what the windows kept (elephant-gallop
    tiled to 250 frames: 249 segments of 249). 0: never search in windows."""
    search_share: float = 0.125
    """With the dense fit, the error-driven search stops at this share of the frame intervals: a clip that
    needs more segments than that has been smaller with a knot at every frame on every benchmark sequence,
    and the search's rounds cost more the more segments they fit."""
    close_sizes: float = 0.15
    """Candidates whose trial sizes lie within this share of each other are close: the one with a clearly
    lower max error is kept, else they are compared at the final zstd level."""
    clearly_lower_max: float = 0.75
    """A close candidate's max error is clearly lower below this share of the other's."""
    split_rms_ratio: float | None = 2.0
    """With an RMS target, an automatically extracted curve whose spatial floor leaves more than this times
    the target at some vertex is split in two (repeatedly); None: no such split."""
    split_rounds: int = 12
    """Rounds of splitting at most (each halves the offending curves; 12 reach single points from 4096)."""
    floor_max_share: float = 0.7
    """With a max target, curves are split until their floor leaves at most this share of it at every vertex
    (the rest is the time fit's and the rounding's)."""
    floor_room: float = 0.5
    """Automatic curves get shorter until the spatial floor's RMS is at most this share of an RMS target."""
    cubic_gain: float = 1.5
    """An item is a natural-spline candidate unless the spline's held-out error (between every other frame)
    exceeds this multiple of straight lines' (pdeanim.model.spline.CUBIC_GAIN)."""
    cubic_slack: float = 1.05
    """A candidate keeps the spline unless the paper's time pairs fit its frames better by more than this
    factor (pdeanim.model.timefit.CUBIC_SLACK)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (the report's ``tolerances``)."""
        return asdict(self)
