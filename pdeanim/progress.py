"""Progress reporting shared by long-running library stages (simulation, fitting, cyclic clips)."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import TextIO

Progress = Callable[[float, str], None]
"""A callback ``progress(fraction, stage)``: fraction in [0, 1] of the whole call, stage e.g.
"simulate 40/100"."""


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


class StderrProgress:
    """A ``Progress`` for the command line: a redrawn status line on a terminal (at most 5 per second), or
    on a pipe or log file one line every ``log_every`` seconds (so short runs stay quiet); ``close()`` ends
    it."""

    def __init__(self, command: str, stream: TextIO | None = None, log_every: float = 5.0):
        self.command, self.stream = command, stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = 0.2 if self.tty else log_every
        self.started = time.monotonic()
        self.last = self.started - self.interval if self.tty else self.started
        self.drawn = False

    def __call__(self, fraction: float, stage: str) -> None:
        now = time.monotonic()
        if now - self.last < self.interval and fraction < 1.0:
            return
        if fraction >= 1.0 and not self.drawn:
            return  # finished before the first report was due: nothing to say
        self.last = now
        percent = 100 * min(max(fraction, 0.0), 1.0)
        text = f"{self.command}: {stage} {percent:5.1f}% ({now - self.started:.0f} s)"
        if self.tty:
            self.stream.write(f"\r{text:<72}")
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.drawn = True

    def close(self) -> None:
        """End the status line (terminal only)."""
        if self.tty and self.drawn:
            self.stream.write("\n")
            self.stream.flush()


def cli_progress(command: str, quiet: bool) -> StderrProgress | None:
    """The progress reporter of a command (None with ``--quiet``); ``PDEANIM_PROGRESS_EVERY`` sets the seconds
    between lines when stderr is not a terminal (default 5)."""
    if quiet:
        return None
    try:
        every = float(os.environ.get("PDEANIM_PROGRESS_EVERY", "5"))
    except ValueError:
        every = 5.0
    return StderrProgress(f"pdeanim {command}", log_every=max(every, 0.0))
