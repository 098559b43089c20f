"""What a result record needs from the library: the versions of the code that produced it, and values made
JSON-safe (numpy scalars and arrays as Python values, non-finite floats as None)."""

from __future__ import annotations

import math
from importlib import metadata
from typing import Any

DISTRIBUTIONS = ("pdeanim", "numpy", "scipy", "trimesh", "pytetwild", "numba", "meshoptimizer")
"""The distributions whose code determines a result."""


def library_versions() -> dict[str, str | None]:
    """Installed version of each of :data:`DISTRIBUTIONS` (None when one is not installed)."""
    out: dict[str, str | None] = {}
    for name in DISTRIBUTIONS:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def jsonable(value: Any) -> Any:
    """``value`` with numpy scalars/arrays as Python values and non-finite floats as None (JSON-safe)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if hasattr(value, "tolist"):
        return jsonable(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, bool | int | str):
        return value
    return str(value)
