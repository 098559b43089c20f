"""What a test does when something it needs is missing: skip on a developer's machine, fail under CI."""

from __future__ import annotations

import os
from typing import NoReturn

import pytest


def in_ci() -> bool:
    """True when ``CI`` is set to a true value (``.ci/run`` exports ``CI=true``)."""
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes", "on")


def missing(reason: str) -> NoReturn:
    """A needed service or tool is unavailable: a failure under CI (a green run must have tested it), else a
    skip with the reason."""
    if in_ci():
        pytest.fail(f"{reason} (CI is set, so a missing service is a failure, not a skip)", pytrace=False)
    pytest.skip(reason)
