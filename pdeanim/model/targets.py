"""Error targets of a fit and the one rule that says whether errors meet them: an error meets its target when
it is at most the target (a zero target is met by a zero error only); a target not given is always met."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Targets:
    """Absolute error targets (None = not requested): RMS and max of the per-vertex distance."""

    rms: float | None = None
    max: float | None = None

    def misses(self, rms: float, largest: float) -> tuple[bool, bool]:
        """(RMS target missed, max target missed) by errors ``rms`` and ``largest``: above the target."""
        return (self.rms is not None and not rms <= self.rms,
                self.max is not None and not largest <= self.max)

    def meets(self, rms: float, largest: float) -> bool:
        """Whether errors ``rms`` and ``largest`` meet every target given."""
        return not any(self.misses(rms, largest))

    def met_by(self, d: np.ndarray) -> bool:
        """Whether per-vertex distances ``d`` (any shape) meet every target given."""
        d = np.asarray(d, np.float64)
        return self.meets(float(np.sqrt(np.mean(d * d))) if d.size else 0.0, float(d.max(initial=0.0)))

    def excess(self, rms: float | np.ndarray, largest: float | np.ndarray) -> float | np.ndarray:
        """How far errors are over the targets: the larger of error / target over the targets given (0 with
        none), elementwise for arrays. At most 1 where the errors meet the targets and at least 1 where they
        miss one; a zero target gives 0 for a zero error and infinity for any other."""
        out = np.zeros(np.broadcast(np.asarray(rms), np.asarray(largest)).shape)
        for error, target in ((rms, self.rms), (largest, self.max)):
            if target is not None:
                out = np.maximum(out, _ratio(np.asarray(error, np.float64), target))
        return out if out.ndim else float(out)


def _ratio(error: np.ndarray, target: float) -> np.ndarray:
    """error / target, with a zero target giving 0 for a zero error and infinity for any other."""
    if target > 0:
        return error / target
    return np.where(error > 0, np.inf, 0.0)
