"""Triangle-set comparison for tests: clip format version 2 stores the triangles in a canonical order."""

from __future__ import annotations

import numpy as np


def canonical(faces: np.ndarray) -> np.ndarray:
    """Each triangle turned (winding kept) to start at its lowest index, rows sorted."""
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    first = np.argmin(f, axis=1)[:, None]
    f = np.take_along_axis(f, (first + np.arange(3)) % 3, axis=1)
    return f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]


def same_triangles(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two face arrays hold the same triangles with the same winding, in any order."""
    return bool(np.array_equal(canonical(a), canonical(b)))
