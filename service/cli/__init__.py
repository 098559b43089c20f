"""The installed ``pdeanim`` console script: the library's commands (:mod:`pdeanim.cli`) plus the
service-side ones (``serve``, ``keys``, ``demo`` here and ``worker`` from :mod:`worker.cli`), so the domain
library never imports the service or the worker."""

from __future__ import annotations

import sys

from pdeanim.cli import main as library_main

SERVICE_COMMANDS = ("service.cli.serve", "worker.cli", "service.cli.keys", "service.cli.demo")

#: argv prefix that runs this console script with the current interpreter (for child processes)
CONSOLE = [sys.executable, "-m", "service.cli"]


def main(argv: list[str] | None = None) -> int:
    """Run one ``pdeanim`` sub-command, library or service side; returns the exit code."""
    return library_main(argv, SERVICE_COMMANDS)
