"""Map mesh vertices to their nearest points of the PDE surface at rest, and move them with those points.

Each vertex gets chain parameters (s, v) and the offset vector from the surface point to the vertex: a
k-d tree over a dense (s, v) sample gives the start, a few damped Gauss-Newton steps on |X(s, v) - p|^2
refine it (all vertices at once). A frame of the mesh is the rest position plus the displacement of the
vertex's surface point, so a zero displacement gives the rest mesh back bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..progress import Progress, no_progress
from .chain import BodySurface
from .spine import split_s


@dataclass(frozen=True)
class VertexMap:
    """Per-vertex surface parameters: s (V,) chain parameter, v (V,) angle, offset (V, 3) vertex - X(s, v)."""

    s: np.ndarray
    v: np.ndarray
    offset: np.ndarray

    def patch_u(self, n_patches: int) -> tuple[np.ndarray, np.ndarray]:
        """The (patch (V,) int, local u (V,)) form of s."""
        return split_s(self.s, n_patches)

    @property
    def distance(self) -> np.ndarray:
        """(V,) distance of each vertex from its surface point."""
        return np.linalg.norm(self.offset, axis=1)


def _gauss_newton_step(surface: BodySurface, p: np.ndarray, s: np.ndarray, v: np.ndarray,
                       x: np.ndarray) -> np.ndarray:
    """Least-squares step (Q, 2) in (s, v) towards p (Q, 3) from X(s, v) = x, by batched QR of the
    Jacobian."""
    jac = np.stack([surface.evaluate(s, v, ds=1), surface.evaluate(s, v, dv=1)], axis=2)  # (Q, 3, 2)
    q, r = np.linalg.qr(jac)
    rhs = np.einsum("qij,qi->qj", q, p - x)
    ok = np.abs(r[:, [0, 1], [0, 1]]).min(axis=1) > 1e-12 * np.abs(r).max(axis=(1, 2))
    r[~ok] = np.eye(2)
    step = np.linalg.solve(r, rhs[..., None])[..., 0]
    step[~ok] = 0.0
    step[:, 0] = np.clip(step[:, 0], -0.5 / surface.n_patches, 0.5 / surface.n_patches)
    step[:, 1] = np.clip(step[:, 1], -0.5, 0.5)
    return step


def _refine(surface: BodySurface, p: np.ndarray, s: np.ndarray, v: np.ndarray, iters: int,
            progress: Progress) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Newton steps on |X(s, v) - p|^2 with backtracking (full, half, quarter, eighth step): a point
    moves only where that lowers its distance, so the result is never worse than the start. Points stop
    iterating once no trial step improves them or the step is negligible."""
    s, v = s.astype(np.float64).copy(), v.astype(np.float64).copy()
    x = surface.evaluate(s, v)
    d2 = np.sum((p - x) ** 2, axis=1)
    active = np.arange(len(p))
    for it in range(iters):
        progress(it / iters, f"map vertices: refine {it + 1}/{iters} ({len(active)} moving)")
        step = _gauss_newton_step(surface, p[active], s[active], v[active], x[active])
        moved = np.zeros(len(active), dtype=bool)
        todo = np.arange(len(active))
        for frac in (1.0, 0.5, 0.25, 0.125):
            idx = active[todo]
            s_new = np.clip(s[idx] + frac * step[todo, 0], 0.0, 1.0)
            v_new = np.mod(v[idx] + frac * step[todo, 1], 2 * np.pi)
            x_new = surface.evaluate(s_new, v_new)
            d2_new = np.sum((p[idx] - x_new) ** 2, axis=1)
            ok = d2_new < d2[idx]
            hit = idx[ok]
            s[hit], v[hit], x[hit], d2[hit] = s_new[ok], v_new[ok], x_new[ok], d2_new[ok]
            moved[todo[ok]] = True
            todo = todo[~ok]
            if not len(todo):
                break
        big = np.abs(step).max(axis=1) > 1e-12
        active = active[moved & big]
        if not len(active):
            break
    return s, v, x


def map_to_surface(surface: BodySurface, points: np.ndarray, *, samples_per_patch: int = 24,
                   samples_around: int = 192, iters: int = 8, progress: Progress | None = None) -> VertexMap:
    """Nearest surface point of every point (V, 3) on the body surface at rest, vectorised over points."""
    p = np.asarray(points, dtype=np.float64)
    grid, s_grid, v_grid = surface.grid(surface.n_patches * samples_per_patch + 1, samples_around)
    _, idx = cKDTree(grid.reshape(-1, 3)).query(p)
    i_s, i_v = np.divmod(idx, samples_around)
    s, v, x = _refine(surface, p, s_grid[i_s], v_grid[i_v], iters, progress or no_progress)
    return VertexMap(s, v, p - x)


def move_with_surface(rest: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """Mesh frames from the displacement of each vertex's surface point.

    rest (V, 3); displacement (V, 3) or (K, V, 3) of the mapped surface points -> same shape, float32.
    """
    return (np.asarray(rest, dtype=np.float32) + np.asarray(displacement, dtype=np.float32)).astype(
        np.float32
    )
