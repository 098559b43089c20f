"""Progress reporting shared by long-running library stages (simulation, fitting, cyclic clips)."""

from __future__ import annotations

from collections.abc import Callable

Progress = Callable[[float, str], None]
"""A callback ``progress(fraction, stage)``: fraction in [0, 1] of the whole call, stage e.g. "simulate
40/100"."""


def no_progress(fraction: float, stage: str) -> None:
    """Progress callback that ignores every report."""


def sub_progress(progress: Progress | None, start: float, stop: float) -> Progress:
    """A callback that maps [0, 1] of a sub-stage onto [start, stop] of ``progress``."""
    if progress is None:
        return no_progress
    span = stop - start

    def report(fraction: float, stage: str) -> None:
        progress(start + span * min(max(fraction, 0.0), 1.0), stage)

    return report
