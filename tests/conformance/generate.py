"""Conformance fixtures shared with the JavaScript client: clips of every kind, motion, parameterisation
and looping mode, with the positions the Python evaluator gives at chosen times.

``python -m tests.conformance.generate OUTDIR`` writes, per case, ``NAME.clip`` (a CLIP file) and
``NAME.expected.bin`` (little-endian float32 (K, V, 3)), plus ``manifest.json`` listing every case's times,
vertex count, bounding-box diagonal and what it covers. Fitted cases go through the real fit and cyclic
pipelines on tiny meshes; synthetic cases encode hand-chosen coefficients that reach every branch of the
evaluator (all four families, D on both sides of D_SWITCH and near 0, trig constants at their cap, a
zero-length segment, large and tiny rigid rotations). Every case is format 1.0; the name says which of its
optional features it covers: "-spline" cases have items on the natural-spline time model (docs/format.md
§3.5), "-basis" cases store their knots on a shared low-rank time basis (§3.4), "-pde" cases were fitted with
the paper's time model alone, "-windows" cases were fitted in windows of frames and store a knot step per
window (§3.4) (the generator checks that the writer did choose what each covers). "bones-" cases are format
1.1 with a bone layer (§3.9, :mod:`tests.conformance.bonecases`); "stream-" cases are format 1.2 conversions
of other cases to the streamable layout (§3.10). ``refused`` lists clips every reader must refuse (a
``required`` feature no reader implements), ``damaged`` streamable clips whose index is damaged.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from pdeanim import container
from pdeanim.clip import ClipParts, load_clip, write_clip_file
from pdeanim.curveset import CurveSet
from pdeanim.cyclic.job import CyclicOptions, make_cyclic_clip
from pdeanim.fit import FitOptions, FitTolerances, fit_poses
from pdeanim.model.clipformat import TIME_SPLINE, CoefficientData, encode_coefficients, encode_topology
from pdeanim.model.families import MU_TRIG_MAX
from pdeanim.model.streamlayout import is_stream, to_stream
from pdeanim.poses import make_poses

from . import bonecases

FIXTURE_VERSION = 13
"""Bumped when the set of cases or their layout changes (the JS tests read the manifest)."""


def _sphere_poses(n_frames: int = 13, loop: bool = False):
    """A 42-vertex icosphere that sways, twists and breathes over n_frames frames (periodic when loop)."""
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    rest = np.asarray(mesh.vertices, np.float64)
    span = n_frames - 1 if loop else n_frames
    frames = []
    for f in range(n_frames):
        ph = 2 * np.pi * f / span
        ang = 0.6 * np.sin(ph) * (rest[:, 2] + 1.0)
        c, s = np.cos(ang), np.sin(ang)
        x = np.stack([c * rest[:, 0] - s * rest[:, 1], s * rest[:, 0] + c * rest[:, 1], rest[:, 2]], 1)
        x *= 1.0 + 0.15 * np.sin(ph + rest[:, 1:2])
        x[:, 0] += 0.3 * np.sin(ph)
        frames.append(x)
    return make_poses(np.stack(frames), np.asarray(mesh.faces), np.arange(n_frames) / 24.0)


def _fit(motion: str, param_mode: str, loop: bool, time_model: str = "auto") -> Callable[[], ClipParts]:
    return lambda: _assert_features(
        fit_poses(_sphere_poses(loop=loop), FitOptions(segments=3, motion=motion, param_mode=param_mode,
                                                       loop=loop, time_model=time_model)),
        spline=False if loop or time_model == "pde" else None)


OFF_ORIGIN = np.array([3000.0, -1500.0, 750.0])
"""Where the off-origin case's sphere sits: coordinates a thousand times its diagonal, so that float32
rounding of a coordinate (about 2^-24 of it) is far above 1e-6 of the diagonal (docs/format.md §6)."""


def _off_origin() -> ClipParts:
    poses = _sphere_poses()
    moved = make_poses(np.asarray(poses.vertices, np.float64) + OFF_ORIGIN, poses.faces, poses.times)
    return fit_poses(moved, FitOptions(segments=3))


def _smooth_pde() -> ClipParts:
    """12 segments over 25 frames of smooth motion with the paper's time model alone: the writer codes the
    knots as second differences."""
    return _assert_features(fit_poses(_sphere_poses(n_frames=25), FitOptions(segments=12, time_model="pde")),
                            spline=False)


def _smooth_spline(motion: str, time_model: str = "auto") -> Callable[[], ClipParts]:
    """The smooth 12-segment fit: its moving items take the natural spline (chosen, or asked for)."""
    return lambda: _assert_features(fit_poses(_sphere_poses(n_frames=25),
                                              FitOptions(segments=12, motion=motion, time_model=time_model)),
                                    spline=True)


def _windows(motion: str) -> ClipParts:
    """A fit in three windows of frames (plain knot tracks, one knot step per window; each window's segments
    its own, a linear segment between windows)."""
    poses = _sphere_poses(n_frames=25)
    parts = fit_poses(poses, FitOptions(target_rel_rms=3e-3, motion=motion),
                      tolerances=FitTolerances(window_fit_values=0, window_values=8 * poses.n_vertices,
                                               knot_basis=False))
    header, arrays = container.unpack(parts.coefficients)
    windows = arrays["knot_windows"].tolist()
    assert len(windows) == 4 and windows[0] == 0 and windows[-1] == header["n_segments"] + 1, arrays
    assert arrays["knot_step"].shape[0] == 3, arrays
    return _assert_features(parts, basis=False)


def _windows_basis() -> ClipParts:
    """A fit in two windows of frames whose knots are on each window's own shared time basis: one knot step
    per item, the windows' bases side by side (each zero outside its window's knots, §3.4)."""
    mesh = trimesh.creation.icosphere(subdivisions=2)  # 162 vertices bending, twisting and travelling
    x = np.asarray(mesh.vertices)[None]
    t = np.linspace(0.0, 1.0, 40)[:, None, None]
    bend = 0.3 * np.sin(2 * np.pi * (1.5 * t + x[..., :1]) + 1.0) * np.array([0.0, 0.0, 1.0])
    twist = 0.2 * np.sin(2 * np.pi * t + 2.0) * x[..., [1, 0, 2]] * np.array([1.0, -1.0, 0.0])
    travel = np.array([1.0, 0.0, 0.0]) * np.sin(np.pi * t + 3.0)
    poses = make_poses((x + bend + twist + travel).astype(np.float32), np.asarray(mesh.faces))
    parts = fit_poses(poses, FitOptions(target_rel_rms=3e-3),
                      tolerances=FitTolerances(window_fit_values=0, window_values=20 * poses.n_vertices,
                                               window_shared_weights=False))
    header, arrays = container.unpack(parts.coefficients)
    basis = arrays["knot_basis"]
    assert "knot_windows" not in arrays and len(parts.report["windows"]) == 2, header
    assert all(w["knot_rank"] > 0 for w in parts.report["windows"]), parts.report["windows"]
    assert np.any(basis[:, :10] != 0) and np.any(basis[:, -10:] != 0) and np.any(basis == 0), basis
    return _assert_features(parts, basis=True)


def _single_frame_rigid() -> ClipParts:
    """A one-frame clip (rigid motion): every t shows that frame."""
    p = _sphere_poses()
    return fit_poses(make_poses(p.vertices[:1], p.faces, p.times[:1]), FitOptions(motion="rigid"))


def _capsule():
    return trimesh.creation.capsule(height=3.0, radius=0.5, count=[10, 10])


def _cyclic(mode: str, **overrides) -> Callable[[], ClipParts]:
    opts = CyclicOptions(mode=mode, overrides=overrides, n_curves=7, points=12, modes=3, frames=8)
    return lambda: make_cyclic_clip(_capsule(), opts)


def _synthetic_topology(param_mode: str) -> tuple[bytes, int, np.ndarray]:
    """A 5 x 6 grid of 30 vertices in 5 curves (vertex order shuffled against curve order)."""
    rng = np.random.default_rng(7)
    gx, gy = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-0.5, 0.5, 5))
    rest = np.stack([gx.ravel(), gy.ravel(), 0.1 * np.sin(3 * gx.ravel())], 1)
    V = len(rest)
    perm = rng.permutation(V)  # curve c holds the grid row c, stored at shuffled vertex indices
    order = perm.astype(np.int32)
    offsets = np.arange(0, V + 1, 6, dtype=np.int32)
    faces = []
    for r in range(4):
        for c in range(5):
            a, b, d, e = r * 6 + c, r * 6 + c + 1, (r + 1) * 6 + c, (r + 1) * 6 + c + 1
            faces += [[a, b, e], [a, e, d]]
    faces = perm[np.asarray(faces)]
    u_row = np.array([0.0, 0.2, 0.5, 0.50004, 0.8, 1.0])  # exact 0, 1/2 (x = 0) and the tiny-x series
    u = np.zeros((V, 3))
    u[perm] = u_row[np.tile(np.arange(6), 5)][:, None]
    if param_mode == "paper":
        u[perm, 1] = rng.uniform(0, 1, V)
        u[perm, 2] = 1.0 - u[perm, 0]
    pos = np.zeros((V, 3))
    pos[perm] = rest
    topo = encode_topology(CurveSet(order, offsets), u, faces, pos, param_mode)
    return topo, 5, pos


def _synthetic_dynamic(motion: str, param_mode: str, loop: bool, spline: bool = False
                       ) -> Callable[[], ClipParts]:
    """Hand-chosen coefficients reaching every branch; ``spline`` puts a random half of the items on the
    natural spline (their constants 0; no zero-length segment then)."""
    def make() -> ClipParts:
        topo, C, _ = _synthetic_topology(param_mode)
        rng = np.random.default_rng(11)
        S = 4
        seg_t = np.array([0.0, 0.3, 0.36 if spline else 0.3, 0.55, 1.0])  # else a zero-length segment
        space = rng.integers(0, 2, (C, 3))
        trig = rng.integers(0, 2, (S, C, 3))
        family = (2 * trig + space[None]).astype(np.uint8)
        m = rng.choice([0.0, 1e-13, 1e-3, 0.4, 2.0, 9.0, 32.0], (S, C, 3))
        m = np.where(trig == 1, rng.choice([0.0, 1e-3, 1.0, MU_TRIG_MAX * 0.9999], (S, C, 3)), m)
        D = np.array([[0.0, 1e-5, 0.5], [2.0, 3.99, 4.0], [4.01, 8.0, 20.0], [1.0, 6.0, 0.05],
                      [3.0, 3.0, 12.0]])
        knots = rng.normal(0, 0.05, (S + 1, C, 3, 4))
        if loop:
            knots[-1] = knots[0]
        extra = {}
        if motion == "rigid":
            Sr = 2
            extra = {"rigid_segment_t": np.array([0.0, 0.5, 1.0]),
                     "rigid_centre": rng.normal(0, 0.3, (C, 3)).astype(np.float32),
                     "rigid_rot_knots": np.concatenate([rng.normal(0, 1.2, (Sr + 1, C - 1, 3)),
                                                        np.full((Sr + 1, 1, 3), 1e-6)], 1).astype(np.float32),
                     "rigid_rot_mu": np.array([[0.0, 2.0, -1.5, 1e-13, -2.9], [5.0, 0.0, -0.5, 0.3, 1.0]],
                                              np.float32),
                     "rigid_trans_knots": rng.normal(0, 0.4, (Sr + 1, C, 3)).astype(np.float32),
                     "rigid_trans_mu": np.array([[-2.0, 0.0, 3.0, -0.1, 0.7], [1.0, -2.5, 0.0, 8.0, 0.0]],
                                                np.float32)}
            if loop:
                for k in ("rigid_rot_knots", "rigid_trans_knots"):
                    extra[k][-1] = extra[k][0]
        model = _time_models(rng, C, spline)
        m = np.where(model[None] == TIME_SPLINE, 0.0, m)
        data = CoefficientData(seg_t, np.linspace(0.0, 2.0, 9), family, m, D, knots, motion, loop,
                               {"errors": {}}, extra, model)
        return _assert_features(ClipParts(topo, encode_coefficients(topo, data)), basis=False, spline=spline)
    return make


def _time_models(rng: np.random.Generator, C: int, spline: bool) -> np.ndarray:
    """(C, 3) uint8 time models: a random half of the items on the spline when ``spline``, else none."""
    return (rng.integers(0, 2, (C, 3)) if spline else np.zeros((C, 3))).astype(np.uint8)


def _blend_poses(n_frames: int = 25, loop: bool = False):
    """The icosphere of _sphere_poses blending towards two morph targets (a squash and a bulge)."""
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    rest = np.asarray(mesh.vertices, np.float64)
    squash = rest * np.array([1.3, 0.8, 1.0]) - rest
    bulge = 0.3 * np.sin(3 * rest[:, [1, 2, 0]])
    span = n_frames - 1
    frames = []
    for f in range(n_frames):
        ph = 2 * np.pi * f / span
        a, b = (0.5 * (1 - np.cos(ph)), 0.5 * np.sin(ph) ** 2) if loop else (f / span, np.sin(2 * ph) ** 2)
        frames.append(rest + a * squash + b * bulge)
    return make_poses(np.stack(frames), np.asarray(mesh.faces), np.arange(n_frames) / 24.0)


def _assert_features(parts: ClipParts, basis: bool | None = None, spline: bool | None = None) -> ClipParts:
    """The case really covers what it says: a 1.0 clip whose knots are (or are not) on a shared basis of rank
    r < S+1 plus residual tracks, and with (or without) items on the natural spline (None: either)."""
    header, arrays = container.unpack(parts.coefficients)
    S, C = header["n_segments"], header["n_curves"]
    assert header["format_version"] == "1.0" and header["knot_differences"] in (1, 2), header
    assert container.unpack(parts.topology)[0]["format_version"] == "1.0"
    assert arrays["knots"].dtype == np.uint32 and arrays["knots"].shape == (C, 3, 4, S + 1)
    r = header["knot_rank"]
    if basis is not None:
        assert (r >= 1) == basis and ("knot_basis" in arrays) == basis, header
    if r:
        assert arrays["knot_weights"].dtype == np.uint32 and arrays["knot_weights"].shape == (r, C, 3, 4)
        assert 1 <= r < S + 1 and arrays["knot_basis"].shape == (r, S + 1)
    model = arrays["time_model"]
    assert model.dtype == np.uint8 and model.shape == (C, 3)
    if spline is not None:
        assert bool((model == TIME_SPLINE).any()) == spline, model
    return parts


def _fit_blend(loop: bool) -> Callable[[], ClipParts]:
    """A fit with an RMS target of a morph-target blend: the fit's own encoder picks the knot basis."""
    return lambda: _assert_features(
        fit_poses(_blend_poses(loop=loop), FitOptions(target_rel_rms=1e-3, loop=loop)), basis=True)


def _synthetic_blend(motion: str, param_mode: str, loop: bool, spline: bool = False
                     ) -> Callable[[], ClipParts]:
    """A morph-target blend: knots that are exactly a blend of three shapes with weights that vary over 11
    segments (rank 3 tracks), encoded with an RMS budget so that the knot basis wins; ``spline`` puts a
    random half of the items on the natural spline (no zero-length segment then)."""
    def make() -> ClipParts:
        topo, C, _ = _synthetic_topology(param_mode)
        rng = np.random.default_rng(13)
        S = 11
        seg_t = np.concatenate([[0.0], np.sort(rng.uniform(0.0, 1.0, S - 1)), [1.0]])
        if not spline:
            seg_t[5] = seg_t[4]  # a zero-length segment
        space = rng.integers(0, 2, (C, 3))
        trig = rng.integers(0, 2, (S, C, 3))
        family = (2 * trig + space[None]).astype(np.uint8)
        m = np.where(trig == 1, rng.choice([0.0, 1e-3, 1.0, MU_TRIG_MAX * 0.9999], (S, C, 3)),
                     rng.choice([0.0, 1e-13, 0.4, 2.0, 9.0], (S, C, 3)))
        D = np.array([[0.0, 1e-5, 0.5], [2.0, 3.99, 4.0], [4.01, 8.0, 20.0], [1.0, 6.0, 0.05],
                      [3.0, 3.0, 12.0]])
        shapes = rng.normal(0, 0.05, (3, C, 3, 4))
        phase = 2 * np.pi * seg_t
        if loop:  # periodic weights: the last knot is the first
            blend = np.stack([np.ones_like(phase), np.sin(phase), 0.5 * (1 - np.cos(2 * phase))])
        else:
            blend = np.stack([np.ones_like(phase), seg_t, np.sin(3 * phase)])
        knots = np.einsum("js,jcwk->scwk", blend, shapes)
        if loop:
            knots[-1] = knots[0]
        extra = {}
        if motion == "rigid":
            extra = {"rigid_segment_t": np.array([0.0, 0.4, 1.0]),
                     "rigid_centre": rng.normal(0, 0.3, (C, 3)).astype(np.float32),
                     "rigid_rot_knots": rng.normal(0, 0.8, (3, C, 3)).astype(np.float32),
                     "rigid_rot_mu": rng.choice([-1.5, 0.0, 2.0], (2, C)).astype(np.float32),
                     "rigid_trans_knots": rng.normal(0, 0.4, (3, C, 3)).astype(np.float32),
                     "rigid_trans_mu": rng.choice([-0.5, 0.0, 3.0], (2, C)).astype(np.float32)}
            if loop:
                for k in ("rigid_rot_knots", "rigid_trans_knots"):
                    extra[k][-1] = extra[k][0]
        model = _time_models(rng, C, spline)
        m = np.where(model[None] == TIME_SPLINE, 0.0, m)
        data = CoefficientData(seg_t, np.linspace(0.0, 2.0, S + 1), family, m, D, knots, motion, loop,
                               {"errors": {}}, extra, model)
        parts = ClipParts(topo, encode_coefficients(topo, data, knot_rms=2e-4))
        return _assert_features(parts, basis=True, spline=spline)
    return make


CASES: dict[str, tuple[Callable[[], ClipParts], dict]] = {
    "fit-displacement-chord": (_fit("displacement", "chord", False), {}),
    "fit-absolute-paper": (_fit("absolute", "paper", False), {}),
    "fit-rigid-chord": (_fit("rigid", "chord", False), {}),
    "fit-displacement-chord-loop": (_fit("displacement", "chord", True), {}),
    "fit-rigid-paper-loop": (_fit("rigid", "paper", True), {}),
    "fit-rigid-single-frame": (_single_frame_rigid, {}),
    "fit-absolute-chord-pde": (_fit("absolute", "chord", False, time_model="pde"), {}),
    "fit-displacement-chord-smooth-pde": (_smooth_pde, {}),
    "fit-displacement-chord-smooth-spline": (_smooth_spline("displacement"), {}),
    "fit-absolute-chord-smooth-spline": (_smooth_spline("absolute"), {}),
    "fit-rigid-chord-smooth-spline": (_smooth_spline("rigid", "spline"), {}),
    "fit-blend-displacement-chord-loop-basis": (_fit_blend(True), {}),
    "fit-displacement-chord-windows": (lambda: _windows("displacement"), {}),
    "fit-absolute-chord-windows": (lambda: _windows("absolute"), {}),
    "fit-displacement-chord-windows-basis": (_windows_basis, {}),
    "synthetic-displacement-paper": (_synthetic_dynamic("displacement", "paper", False), {}),
    "synthetic-absolute-chord-loop": (_synthetic_dynamic("absolute", "chord", True), {}),
    "synthetic-rigid-paper": (_synthetic_dynamic("rigid", "paper", False), {}),
    "synthetic-rigid-chord-loop": (_synthetic_dynamic("rigid", "chord", True), {}),
    "synthetic-displacement-chord-spline": (_synthetic_dynamic("displacement", "chord", False, True), {}),
    "synthetic-rigid-paper-spline": (_synthetic_dynamic("rigid", "paper", False, True), {}),
    "synthetic-absolute-paper-loop-spline": (_synthetic_dynamic("absolute", "paper", True, True), {}),
    "synthetic-blend-displacement-paper-basis": (_synthetic_blend("displacement", "paper", False), {}),
    "synthetic-blend-rigid-chord-loop-basis": (_synthetic_blend("rigid", "chord", True), {}),
    "synthetic-blend-absolute-chord-basis-spline": (_synthetic_blend("absolute", "chord", False, True), {}),
    "cyclic-eel-standing-rotate": (_cyclic("eel"), {}),
    "cyclic-dolphin-travelling-translate": (_cyclic("dolphin", wave="travelling", radial="translate"), {}),
    "cyclic-trout-travelling-rotate-vertical": (_cyclic("trout", wave="travelling", direction="vertical"),
                                                {}),
    "fit-displacement-chord-off-origin": (_off_origin, {}),
    "bones-synthetic-k1-zero": (bonecases.synthetic_bone_case(1, 2, residual=False), {}),
    "bones-synthetic-k2-residual": (bonecases.synthetic_bone_case(2, 3, residual=True, differences=2), {}),
    "bones-synthetic-k3-zero-loop": (bonecases.synthetic_bone_case(3, 4, residual=False, looping=True), {}),
    "bones-synthetic-k4-residual": (bonecases.synthetic_bone_case(4, 5, residual=True), {}),
    "bones-fit-k2-zero": (bonecases.fitted_bone_case(2, 3, residual=False), {}),
    "bones-fit-k4-residual": (bonecases.fitted_bone_case(4, 5, residual=True), {}),
}

def _stream(name: str, window_seconds: float = 0.1) -> Callable[[], ClipParts]:
    """Case ``name`` in the streamable layout (format 1.2, §3.10), windows of ``window_seconds`` (the
    sphere's 13 frames last half a second: several windows)."""
    def make() -> ClipParts:
        parts = to_stream(CASES[name][0](), window_seconds=window_seconds)
        return parts
    return make


CASES.update({
    "stream-fit-displacement-chord": (_stream("fit-displacement-chord", 2.0), {}),  # one window
    "stream-fit-displacement-chord-windows": (_stream("fit-displacement-chord-windows"), {}),
    "stream-fit-displacement-chord-smooth-pde": (_stream("fit-displacement-chord-smooth-pde"), {}),
    "stream-fit-rigid-chord-smooth-spline": (_stream("fit-rigid-chord-smooth-spline"), {}),
    "stream-synthetic-absolute-paper-loop-spline": (_stream("synthetic-absolute-paper-loop-spline", 0.5), {}),
    "stream-synthetic-blend-absolute-chord-basis-spline": (
        _stream("synthetic-blend-absolute-chord-basis-spline", 0.3), {}),
    "stream-bones-synthetic-k2-residual": (_stream("bones-synthetic-k2-residual"), {}),
    "stream-bones-synthetic-k3-zero-loop": (_stream("bones-synthetic-k3-zero-loop"), {}),
})
"""The "stream-" cases are format 1.2 (feature "stream", docs/format.md §3.10) conversions of other cases: the
expected positions are the stream clip's (equal to the source's but near inner window bounds of spline
items, §3.10); their manifest entry has a ``stream`` object."""


def _future_stream() -> ClipParts:
    """A streamable clip that also requires a feature no reader implements."""
    parts = to_stream(_fit("displacement", "chord", False)(), window_seconds=0.1)
    coefficients = container.with_header(parts.coefficients, {"required": ["stream", FUTURE_STREAM]})
    return ClipParts(parts.topology, coefficients)


FUTURE_STREAM = "x-future-stream"

REFUSED: dict[str, tuple[Callable[[], ClipParts], str]] = {
    "refused-unknown-feature": (bonecases.unknown_feature_case, bonecases.UNKNOWN_FEATURE),
    "refused-stream-unknown-feature": (_future_stream, FUTURE_STREAM),
}
"""Clips every reader must refuse, with the text the refusal names (the feature it lacks)."""


def _damaged_index(edit: Callable[[dict], None]) -> Callable[[], ClipParts]:
    def make() -> ClipParts:
        parts = to_stream(_fit("displacement", "chord", False)(), window_seconds=0.1)
        stream = json.loads(json.dumps(container.read_header(parts.coefficients)["stream"]))
        edit(stream)
        return ClipParts(parts.topology, container.with_header(parts.coefficients, {"stream": stream}))
    return make


DAMAGED: dict[str, Callable[[], ClipParts]] = {
    "damaged-stream-offset": _damaged_index(lambda s: s["windows"][1].update(
        offset=s["windows"][1]["offset"] + 8)),
    "damaged-stream-times": _damaged_index(lambda s: s["windows"][1]["t"].__setitem__(0, 0.01)),
}
"""Streamable clips whose index disagrees with their arrays (a window's byte offset; a window's start time):
every reader must refuse them, naming a "damaged stream index"."""


TOLERANCE_REL_COORDINATE = 2.0**-20
"""Of the largest coordinate magnitude of a case's positions, added to 1e-6 of its diagonal: float32 keeps
about 2^-24 of a coordinate, and evaluators that round in another order differ by a few of those."""


def case_times(parts: ClipParts) -> list[float]:
    """t = 0 and 1, every segment boundary (rigid ones too), midpoints, clamping or loop wrap."""
    ch, ca = container.unpack(parts.coefficients)
    ts = {0.0, 1.0, 0.37, 0.999}
    if is_stream(ch):  # the windows' boundaries (each window holds its own)
        for w in ch["stream"]["windows"]:
            _, wa = container.unpack(ca[w["array"]].tobytes())
            ca = {**ca, **{name: np.concatenate([ca.get(name, np.zeros(0)), wa[name]])
                           for name in ("segment_t", "bone_segment_t") if name in wa}}
    for name in ("segment_t", "rigid_segment_t", "bone_segment_t"):
        if name in ca:
            b = sorted({float(x) for x in ca[name]})
            ts.update(b)
            ts.update(0.5 * (x + y) for x, y in zip(b, b[1:], strict=False))
    looping = bool(ch.get("looping", False)) or ch.get("kind") == "cyclic-spine"
    ts.update([1.25, -0.3, 2.0, -1.0] if looping else [-0.5, 1.5])
    return sorted(ts)


def generate(out: Path, names: list[str] | None = None) -> dict:
    """Write the fixture files of the chosen cases (all by default) into out; returns the manifest."""
    out.mkdir(parents=True, exist_ok=True)
    manifest: dict = {"fixture_version": FIXTURE_VERSION, "tolerance_rel_diagonal": 1e-6,
                      "tolerance_rel_coordinate": TOLERANCE_REL_COORDINATE, "cases": []}
    for name, (make, _) in CASES.items():
        if names and name not in names:
            continue
        parts = make()
        parts.report = {}  # timings would make the files differ run to run
        write_clip_file(out / f"{name}.clip", parts)
        clip = load_clip(parts.topology, parts.coefficients)
        ts = case_times(parts)
        pos = np.asarray(clip.evaluate(np.asarray(ts)), np.float32)
        (out / f"{name}.expected.bin").write_bytes(pos.astype("<f4").tobytes())
        th, _ = container.unpack(parts.topology)
        ch, ca = container.unpack(parts.coefficients)
        rest = np.asarray(clip.evaluate(0.0), np.float64)
        manifest["cases"].append({
            "name": name, "clip": f"{name}.clip", "expected": f"{name}.expected.bin", "kind": clip.kind,
            "motion": ch.get("motion"), "param_mode": th.get("param_mode"), "looping": bool(clip.looping),
            "format_version": ch.get("format_version"), "knot_rank": ch.get("knot_rank"),
            "spline_items": int((ca["time_model"] == TIME_SPLINE).sum()) if "time_model" in ca else None,
            "n_vertices": int(clip.n_vertices), "t": ts,
            "diagonal": float(np.linalg.norm(np.ptp(rest, axis=0))),
            **({"bones": bones} if (bones := bonecases.bone_manifest(parts)) else {}),
            **({"stream": _stream_manifest(ch)} if is_stream(ch) else {})})
    for name, (make, feature) in REFUSED.items():
        if names and name not in names:
            continue
        write_clip_file(out / f"{name}.clip", make())
        manifest.setdefault("refused", []).append({"name": name, "clip": f"{name}.clip", "names": feature})
    for name, make in DAMAGED.items():
        if names and name not in names:
            continue
        write_clip_file(out / f"{name}.clip", make())
        manifest.setdefault("damaged", []).append({"name": name, "clip": f"{name}.clip",
                                                   "message": "damaged stream index"})
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest


def _stream_manifest(header: dict) -> dict:
    """The manifest's summary of a streamable case: windows, their knots and times, the carried rules."""
    windows = header["stream"]["windows"]
    return {"n_windows": len(windows), "knots": [w["knots"] for w in windows],
            "t": [w["t"] for w in windows], "knot_differences": header["knot_differences"],
            "required": header["required"]}


def main(argv: list[str] | None = None) -> int:
    """Command line: python -m tests.conformance.generate OUTDIR [CASE ...]."""
    args = sys.argv[1:] if argv is None else argv
    if not args:
        print("usage: python -m tests.conformance.generate OUTDIR [CASE ...]", file=sys.stderr)
        return 2
    manifest = generate(Path(args[0]), args[1:] or None)
    print(f"wrote {len(manifest['cases'])} conformance cases to {args[0]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
