"""XPBD time stepping (Macklin et al. 2016) with small steps (Macklin et al. 2019) over coloured tets.

An immutable rest model (:class:`SimModel`) holds everything derived from the tet mesh and the material; a
:class:`SimState` holds positions, velocities and time; ``step(model, state_in, state_out, dt)`` advances one
substep. Compliances come from Lame parameters times rest volume, so the stiffness the solver converges to
does
not depend on iteration count or resolution; steps too long for the material's waves make any XPBD softer
than it should be (``simulate.auto_substeps`` picks them short enough). Inverse masses are lumped from
density.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError
from . import kernels
from .coloring import partitioned_colors
from .constraints import deviatoric_correction, hydrostatic_correction
from .tetmesh import TetMesh

PARTS = 2
"""Independent tet groups of a mesh with at least ``kernels.PARALLEL_MIN_TETS`` tets (one per core of the
two-core target). Fixed, not taken from the thread count, so that results do not depend on it."""

Kinematic = Callable[[float], np.ndarray]
"""``positions(t) -> (K, 3)`` prescribed positions of the model's fixed points at time t."""


@dataclass(frozen=True)
class Material:
    """Young's modulus (Pa), Poisson ratio, density (kg/m^3) and mass-proportional velocity damping (1/s)."""

    young: float = 1e6
    poisson: float = 0.3
    density: float = 1000.0
    damping: float = 1.0

    def __post_init__(self) -> None:
        if not (self.young > 0 and 0.0 <= self.poisson < 0.5 and self.density > 0 and self.damping >= 0):
            raise ParameterError("material needs young > 0, 0 <= poisson < 0.5, density > 0, damping >= 0")

    def lame(self) -> tuple[float, float]:
        """(mu, lambda) of linear elasticity."""
        mu = self.young / (2.0 * (1.0 + self.poisson))
        lam = self.young * self.poisson / ((1.0 + self.poisson) * (1.0 - 2.0 * self.poisson))
        return mu, lam


@dataclass(frozen=True)
class Ground:
    """A half-space (x - point) . normal >= 0 the points must stay in; friction in [0, 1] damps sliding."""

    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 1.0, 0.0)
    friction: float = 0.0


@dataclass(frozen=True)
class Elements:
    """Tets in colour order: colour c is rows offsets[c]:offsets[c + 1] (no shared point within a colour).

    tets (M, 4) int64, dm_inv (M, 3, 3) rest inverses, w (M, 4) corner inverse masses, alpha_d and alpha_h
    (M,)
    compliances of the deviatoric and volume constraints, offsets (C + 1,) int64; parts (P + 1,) int64 colour
    bounds of P groups that share no point (solved in parallel), then the remaining colours; cst the same
    constants packed in chunks, struct-of-arrays, and chunks (C + 1,) int64 each colour's first chunk, for the
    numba kernels (:func:`kernels.pack_constants`).
    """

    tets: np.ndarray
    dm_inv: np.ndarray
    w: np.ndarray
    alpha_d: np.ndarray
    alpha_h: np.ndarray
    offsets: np.ndarray
    parts: np.ndarray
    cst: np.ndarray
    chunks: np.ndarray

    @property
    def n_colors(self) -> int:
        return len(self.offsets) - 1


@dataclass(frozen=True)
class SimModel:
    """The immutable rest model: points (N, 3), inverse masses (N,), coloured elements, forces,
    constraints."""

    rest: np.ndarray
    inv_mass: np.ndarray
    elements: Elements
    gravity: np.ndarray
    damping: float
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    kinematic: Kinematic | None = None
    ground: Ground | None = None
    iterations: int = 1
    backend: str = "numba" if kernels.AVAILABLE else "numpy"


@dataclass
class SimState:
    """Positions x (N, 3), velocities v (N, 3), rotation guesses rot (M, 4) (w, x, y, z) per element, time
    t."""

    x: np.ndarray
    v: np.ndarray
    rot: np.ndarray
    t: float = 0.0

    def copy(self) -> SimState:
        """A deep copy (the solver writes into state_out)."""
        return SimState(self.x.copy(), self.v.copy(), self.rot.copy(), self.t)


def lumped_masses(tets: TetMesh, density: float) -> np.ndarray:
    """(N,) point masses: a quarter of each adjacent tet's mass."""
    vol = tets.volumes()
    return np.bincount(tets.tets.ravel(), np.repeat(density * vol / 4.0, 4), minlength=tets.n_points)


def build_model(tets: TetMesh, material: Material, gravity: tuple[float, float, float] = (0.0, -9.81, 0.0),
                fixed: np.ndarray | None = None,
                kinematic: Kinematic | None = None, ground: Ground | None = None, iterations: int = 1,
                backend: str | None = None) -> SimModel:
    """Precompute rest shapes, masses, compliances and the colouring; ``fixed`` points get zero inverse
    mass."""
    backend = backend or ("numba" if kernels.AVAILABLE else "numpy")
    if backend not in ("numba", "numpy") or (backend == "numba" and not kernels.AVAILABLE):
        raise ParameterError(f"solver backend {backend!r} is not available")
    fixed = np.zeros(0, np.int64) if fixed is None else np.unique(np.asarray(fixed, np.int64))
    inv_mass = 1.0 / lumped_masses(tets, material.density)
    inv_mass[fixed] = 0.0
    mu, lam = material.lame()
    lam = max(lam, 1e-9 * mu)  # Poisson 0: (almost) no volume stiffness, but a finite compliance
    p = tets.points[tets.tets]
    dm_inv = np.linalg.inv((p[:, 1:] - p[:, :1]).transpose(0, 2, 1))
    vol = tets.volumes()
    colors, parts = partitioned_colors(
        tets.tets, tets.points, PARTS if tets.n_tets >= kernels.PARALLEL_MIN_TETS else 1
    )
    order = np.concatenate(colors)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in colors])]).astype(np.int64)
    t = np.ascontiguousarray(tets.tets[order])
    dm_inv, w = np.ascontiguousarray(dm_inv[order]), np.ascontiguousarray(inv_mass[t])
    alpha_d, alpha_h = 1.0 / (2.0 * mu * vol[order]), 1.0 / (lam * vol[order])
    cst, chunks = kernels.pack_constants(dm_inv, w, alpha_d, alpha_h, offsets)
    elements = Elements(t, dm_inv, w, alpha_d, alpha_h, offsets, parts, cst, chunks)
    return SimModel(tets.points.copy(), inv_mass, elements, np.asarray(gravity, np.float64),
                    material.damping, fixed, kinematic, ground, max(int(iterations), 1), backend)


def rest_state(model: SimModel) -> SimState:
    """The state at rest: rest positions (fixed points at their t = 0 positions), zero velocity."""
    x = model.rest.copy()
    if model.kinematic is not None and len(model.fixed):
        x[model.fixed] = model.kinematic(0.0)
    rot = np.zeros((len(model.elements.tets), 4))
    rot[:, 0] = 1.0
    return SimState(x, np.zeros_like(x), rot, 0.0)


def step(model: SimModel, state_in: SimState, state_out: SimState, dt: float) -> None:
    """Advance one substep of length dt from state_in into state_out (which may not alias state_in)."""
    x = state_out.x
    damp, dv = np.exp(-model.damping * dt), dt * model.gravity
    if model.backend == "numba":
        kernels.predict(state_in.x, state_in.v, model.inv_mass, damp, dv, dt, x)
    else:
        v = state_in.v * damp + dv * (model.inv_mass > 0)[:, None]
        np.add(state_in.x, dt * v, out=x)
    t = state_in.t + dt
    if len(model.fixed):
        x[model.fixed] = model.kinematic(t) if model.kinematic is not None else state_in.x[model.fixed]
    solve_constraints(model, x, dt, state_out.rot, state_in.rot)
    if model.ground is not None:
        project_ground(model.ground, x, state_in.x, model.backend == "numba")
    np.subtract(x, state_in.x, out=state_out.v)
    state_out.v /= dt
    state_out.t = t


def solve_constraints(model: SimModel, x: np.ndarray, dt: float, rot: np.ndarray,
                      rot_in: np.ndarray | None = None) -> None:
    """Gauss-Seidel over colours (all tets of one colour in one pass), in place on x (N, 3) and rot (M, 4).

    rot_in (M, 4), when given, holds the rotation guesses to start from (rot is then only written).
    """
    e = model.elements
    inv_dt2 = 1.0 / (dt * dt)
    if model.backend == "numba":
        lam = np.zeros((2, len(e.tets) if model.iterations > 1 else 0))  # one sweep: every lambda starts at 0
        for i in range(model.iterations):
            kernels.solve_sweep(x, rot if rot_in is None or i else rot_in, rot, e.tets, e.cst, lam, inv_dt2,
                                e.offsets, e.chunks, e.parts)
        return
    if rot_in is not None:
        rot[:] = rot_in
    lam_d, lam_h = np.zeros(len(e.tets)), np.zeros(len(e.tets))
    for _ in range(model.iterations):
        for c in range(e.n_colors):
            s = slice(e.offsets[c], e.offsets[c + 1])
            t = e.tets[s]
            dx, dlam, rot[s] = deviatoric_correction(
                x[t], e.w[s], e.dm_inv[s], e.alpha_d[s] * inv_dt2, lam_d[s], rot[s]
            )
            x[t] += dx
            lam_d[s] += dlam
            dx, dlam = hydrostatic_correction(x[t], e.w[s], e.dm_inv[s], e.alpha_h[s] * inv_dt2, lam_h[s])
            x[t] += dx
            lam_h[s] += dlam


def project_ground(
    ground: Ground, x: np.ndarray, x_prev: np.ndarray, compiled: bool = kernels.AVAILABLE
) -> None:
    """Move points behind the ground plane onto it; friction removes part of their sliding this substep."""
    n = np.asarray(ground.normal, np.float64)
    n = n / np.linalg.norm(n)
    if compiled:  # one compiled pass instead of ~10 numpy calls per substep
        kernels.ground(
            x, x_prev, np.asarray(ground.point, np.float64), n, min(max(ground.friction, 0.0), 1.0)
        )
        return
    depth = (x - np.asarray(ground.point, np.float64)) @ n
    hit = depth < 0
    if not hit.any():
        return
    x[hit] -= depth[hit, None] * n
    if ground.friction > 0:
        d = x[hit] - x_prev[hit]
        tangential = d - (d @ n)[:, None] * n
        x[hit] -= min(ground.friction, 1.0) * tangential
