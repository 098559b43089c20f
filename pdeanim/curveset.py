"""CurveSet: a partition of a mesh's vertices into ordered curves, the unit the dynamic-PDE model fits.

Produced by curve extraction (:mod:`pdeanim.curves`), consumed by the fit (:mod:`pdeanim.model`) and
stored in a clip's topology part. Every vertex lies on exactly one curve; a curve may have 1 or 2 points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class CurveSet:
    """Curves as a flat vertex order plus offsets (CSR layout).

    order : (V,) int32, vertex indices curve by curve, each vertex exactly once
    offsets : (C + 1,) int32, curve c is ``order[offsets[c]:offsets[c + 1]]``; offsets[0] == 0
    """

    order: np.ndarray
    offsets: np.ndarray

    @property
    def n_curves(self) -> int:
        return int(len(self.offsets) - 1)

    @property
    def lengths(self) -> np.ndarray:
        """(C,) number of points on each curve."""
        return np.diff(self.offsets)

    def curve_of_vertex(self, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
        """(V,) curve id and (V,) position along its curve for every vertex; -1 where no curve holds one."""
        curve = np.repeat(np.arange(self.n_curves, dtype=np.int32), self.lengths)
        pos = np.arange(len(self.order), dtype=np.int32) - np.repeat(self.offsets[:-1], self.lengths)
        cid = np.full(n_vertices, -1, np.int32)
        idx = np.full(n_vertices, -1, np.int32)
        cid[self.order] = curve
        idx[self.order] = pos
        return cid, idx

    def padded(self) -> tuple[np.ndarray, np.ndarray]:
        """(C, Nmax) vertex index matrix (padding repeats the curve's last vertex) and (C, Nmax) bool mask."""
        lengths = self.lengths
        nmax = int(lengths.max()) if len(lengths) else 0
        j = np.arange(nmax)[None, :]
        mask = j < lengths[:, None]
        pos = self.offsets[:-1, None] + np.minimum(j, np.maximum(lengths[:, None] - 1, 0))
        return self.order[pos], mask

    def validate(self, n_vertices: int) -> CurveSet:
        """Check that the curves partition range(n_vertices); raises InputError otherwise."""
        o, off = np.asarray(self.order), np.asarray(self.offsets, np.int64)  # int64: no wrapping differences
        if off.ndim != 1 or len(off) < 1 or off[0] != 0 or off[-1] != len(o) or np.any(np.diff(off) < 1):
            raise InputError("curve offsets must start at 0, end at len(order) and give non-empty curves")
        if len(o) != n_vertices or not np.array_equal(np.sort(o), np.arange(n_vertices)):
            raise InputError("curves must contain every vertex exactly once")
        return self

    @staticmethod
    def from_lists(curves: list[list[int]] | list[np.ndarray]) -> CurveSet:
        """Build from a list of vertex-index sequences (convenience for tests and small inputs)."""
        lengths = np.array([len(c) for c in curves], dtype=np.int64)
        order = (
            np.concatenate([np.asarray(c, dtype=np.int32) for c in curves])
            if curves
            else np.zeros(0, np.int32)
        )
        offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
        return CurveSet(order.astype(np.int32), offsets)
