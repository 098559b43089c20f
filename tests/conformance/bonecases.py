"""Conformance cases with a bone layer (format 1.1, docs/format.md §3.9), and one that requires an unknown
feature: hand-chosen bone tracks that reach every branch of the bone evaluation (paper pairs exp / trig /
linear, spline channels, 1..4 influences, a zero weight, rotations below the small-angle switch and near
pi), on a zero residual and on fitted residual curves, plus a fitted bone layer (encode_bones) on a bending
tube."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pdeanim import container
from pdeanim.clip import ClipParts
from pdeanim.fit import FitOptions, fit_poses
from pdeanim.model.bonelayer import (
    CHANNELS,
    TIME_SPLINE,
    BoneMotion,
    EncodedBones,
    encode_bones,
    repack_with_bone_layer,
    skinned_positions,
    weight_levels,
)
from pdeanim.model.clipformat import CoefficientData, decode_topology, encode_coefficients
from pdeanim.model.families import MU_TRIG_MAX
from pdeanim.poses import make_poses

UNKNOWN_FEATURE = "x-future-feature"


def tube(n_rings: int = 9, sections: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(rest (V, 3), faces (T, 3)): an open tube of radius 0.2 along z from -1 to 1 (72 vertices)."""
    z = np.linspace(-1.0, 1.0, n_rings)
    a = 2 * np.pi * np.arange(sections) / sections
    rest = np.stack([np.tile(0.2 * np.cos(a), n_rings), np.tile(0.2 * np.sin(a), n_rings),
                     np.repeat(z, sections)], 1)
    faces = []
    for r in range(n_rings - 1):
        for s in range(sections):
            p, q = r * sections + s, r * sections + (s + 1) % sections
            faces += [[p, q, q + sections], [p, q + sections, p + sections]]
    return rest, np.asarray(faces)


def tube_weights(rest: np.ndarray, pivot: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray]:
    """(index (V, K), weight (V, K)): the K bones nearest along z, weights falling with distance."""
    d = np.abs(rest[:, 2, None] - pivot[None, :, 2])
    index = np.argsort(d, axis=1, kind="stable")[:, :K]
    w = 1.0 / (np.take_along_axis(d, index, 1) + 0.15) ** 2
    return index, w / w.sum(axis=1, keepdims=True)


def bend_motion(n_frames: int, B: int, K: int, loop: bool = False
                ) -> tuple[np.ndarray, np.ndarray, BoneMotion]:
    """(rest, faces, motion): B bones along the tube waving (frame 0 the rest pose) and drifting."""
    rest, faces = tube()
    pivot = np.stack([np.zeros(B), np.zeros(B), np.linspace(-1.0, 0.6, B)], 1)
    index, weight = tube_weights(rest, pivot, K)
    ph = 2 * np.pi * np.arange(n_frames) / (n_frames - 1 if loop else n_frames)
    amp = np.linspace(0.2, 0.9, B)
    rot = np.zeros((n_frames, B, 3))
    rot[:, :, 0] = amp * np.sin(ph)[:, None]
    rot[:, :, 1] = 0.3 * amp * (1 - np.cos(ph))[:, None]
    trans = np.zeros((n_frames, B, 3))
    trans[:, :, 0] = 0.15 * np.sin(ph)[:, None]
    trans[:, :, 2] = 0.05 * np.sin(2 * ph)[:, None] * np.arange(B)
    return rest, faces, BoneMotion(pivot, index, weight, rot, trans)


def synthetic_bones(V: int, B: int, K: int, seed: int, differences: int = 1) -> EncodedBones:
    """Hand-chosen bone tracks over 3 bone segments: every channel time model and pair branch, one rotation
    below the small-angle switch, one near pi; influences 0..K-1 with a zero weight in some rows."""
    rng = np.random.default_rng(seed)
    seg_t = np.array([0.0, 0.25, 0.6, 1.0])
    Sb = 3
    model = rng.integers(0, 2, (B, CHANNELS)).astype(np.uint8)
    model[0, :3] = [0, 1, 0]  # both models present whatever the seed
    mu = rng.choice([0.0, 1e-13, 0.4, 3.0, 20.0, -1e-3, -1.0, -MU_TRIG_MAX * 0.9999], (Sb, B, CHANNELS))
    mu = np.where(model[None] == TIME_SPLINE, 0.0, mu).astype(np.float32)
    step = (2.0 ** rng.integers(-12, -8, (B, CHANNELS))).astype(np.float32)
    values = rng.normal(0.0, 0.5, (Sb + 1, B, CHANNELS))
    values[:, :, 3:] *= 0.3
    values[:, 0, :3] *= 1e-5  # bone 0 turns below 1e-4 rad: the small-angle branch
    if B > 1:
        values[:, 1, :3] = np.array([0.0, 0.0, 3.0]) + 0.05 * rng.normal(size=(Sb + 1, 3))  # near pi
    codes = np.rint(values / step.astype(np.float64)[None]).astype(np.int64)
    index = rng.integers(0, B, (V, K)).astype(np.uint16)  # in no particular order, repeats allowed
    raw = rng.uniform(0.05, 1.0, (V, K))
    if K > 1:
        raw[::5, K - 1] = 0.0  # the implied last weight 0
        raw[1::7, 0] = 0.0  # a zero weight first
        raw[raw.sum(axis=1) == 0, K // 2] = 1.0  # every vertex keeps an influence
    bits = (8, 12, 16, 5)[seed % 4]
    weight = weight_levels(raw / raw.sum(axis=1, keepdims=True), 2**bits - 1).astype(np.uint16)
    pivot = rng.normal(0.0, 0.4, (B, 3)).astype(np.float32)
    return EncodedBones(seg_t, pivot, index, weight, model, mu, step, codes, differences, bits)


def _zero_curves(topo: bytes, C: int, looping: bool, bones: EncodedBones) -> bytes:
    """A coefficients part whose curves are all zero (a pure bone clip) over 2 segments, with the bones."""
    S = 2
    data = CoefficientData(np.array([0.0, 0.5, 1.0]), np.linspace(0.0, 1.5, 7), np.zeros((S, C, 3), np.uint8),
                           np.zeros((S, C, 3)), np.zeros((C, 3)), np.zeros((S + 1, C, 3, 4)), "displacement",
                           looping, {"errors": {}}, time_model=np.zeros((C, 3), np.uint8), bones=bones)
    return encode_coefficients(topo, data)


def synthetic_bone_case(K: int, B: int, residual: bool, looping: bool = False, differences: int = 1
                        ) -> Callable[[], ClipParts]:
    """A hand-made bone layer on the 30-vertex synthetic grid: zero curves, or a fitted residual."""
    from .generate import _synthetic_topology

    def make() -> ClipParts:
        topo, C, rest = _synthetic_topology("chord")
        bones = synthetic_bones(len(rest), B, K, seed=20 + 4 * K + B, differences=differences)
        if not residual:
            return ClipParts(topo, _zero_curves(topo, C, looping, bones))
        grid = rest.astype(np.float32).astype(np.float64)
        n = 9
        t = np.linspace(0.0, 1.0, n)
        wave = 0.05 * np.sin(2 * np.pi * t[:, None] + 3 * grid[None, :, 0])[..., None] * np.array([0, 0, 1.0])
        poses = make_poses(grid[None] + wave, _grid_faces(topo), t * 2.0)
        parts = fit_poses(poses, FitOptions(segments=3))
        return ClipParts(parts.topology, repack_with_bone_layer(parts.coefficients, bones))
    return make


def _grid_faces(topo: bytes) -> np.ndarray:
    """The triangles of a topology part."""
    return np.asarray(decode_topology(*container.unpack(topo)).faces)


def fitted_bone_case(K: int, B: int, residual: bool) -> Callable[[], ClipParts]:
    """encode_bones on a waving tube (B bones, K influences, 17 frames): the pure skinned motion (zero
    residual) or the skinned motion plus a bulge the bones cannot make, fitted as residual curves."""
    def make() -> ClipParts:
        rest, faces, motion = bend_motion(17, B, K)
        times = np.arange(17) / 24.0
        rest32 = rest.astype(np.float32)
        diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
        enc = encode_bones(motion, times, 1e-3 * diag, rest32)
        t = (times - times[0]) / (times[-1] - times[0])
        skinned = skinned_positions(enc, rest32, t).astype(np.float64)
        bulge = np.zeros_like(skinned)
        if residual:
            bulge = 0.03 * np.sin(2 * np.pi * t)[:, None, None] * rest[None] * np.array([1.0, 1.0, 0.0])
        residual_poses = rest32.astype(np.float64)[None] + bulge  # what the bones leave, on the rest pose
        parts = fit_poses(make_poses(residual_poses, faces, times), FitOptions(segments=4))
        return ClipParts(parts.topology, repack_with_bone_layer(parts.coefficients, enc))
    return make


def unknown_feature_case() -> ClipParts:
    """A clip whose coefficients part requires a feature no reader implements (format "1.2")."""
    from .generate import _synthetic_topology

    topo, C, _ = _synthetic_topology("chord")
    coef = _zero_curves(topo, C, False, synthetic_bones(30, 2, 2, seed=5))
    header, arrays = container.unpack(coef)
    header.update(format_version="1.2", required=["bones", UNKNOWN_FEATURE])
    return ClipParts(topo, container.pack(header, arrays))


def bone_manifest(parts: ClipParts) -> dict | None:
    """The manifest's summary of a case's bone layer (None without one)."""
    header, arrays = container.unpack(parts.coefficients)
    if "bones" not in header.get("required", []):
        return None
    model = arrays["bone_time_model"]
    if "stream" in header.get("required", []):  # the streamable layout: knots and bone times per window
        windows = [container.unpack(arrays[w["array"]].tobytes())[1] for w in header["stream"]["windows"]]
        curves_zero = not any(np.any(w["knots"]) for w in windows)
        segments = header["stream"]["windows"][-1]["bone_knots"][1]
    else:
        curves_zero = not np.any(arrays["knots"])  # zigzag code 0 everywhere: every knot is 0
        segments = int(len(arrays["bone_segment_t"]) - 1)
    return {"n_bones": header["n_bones"], "influences": header["bone_influences"],
            "bone_segments": segments,
            "spline_channels": int((model == TIME_SPLINE).sum()), "pair_channels": int((model == 0).sum()),
            "bone_knot_differences": header["bone_knot_differences"],
            "bone_weight_bits": header["bone_weight_bits"], "residual_zero": curves_zero}
