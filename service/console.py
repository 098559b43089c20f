"""The argv prefix that runs the ``pdeanim`` console script with the current interpreter, for the child
processes the launcher and ``pdeanim serve --with-workers`` start (standard library only: the console script
imports it before it knows whether the service extra is installed)."""

from __future__ import annotations

import sys

CONSOLE = [sys.executable, "-m", "pdeanim_service.cli"]
