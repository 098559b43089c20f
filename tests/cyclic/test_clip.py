"""The "cyclic-spine" clip kind: the Clip protocol, rest reproduction, the loop and a valid looping GLB."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from pdeanim import container
from pdeanim.clip import Clip, ClipParts, load_clip, read_clip_file, write_clip_file
from pdeanim.cyclic.clipcyclic import clip_from_parts
from pdeanim.errors import ClipFormatError
from pdeanim.gltf.clipexport import clip_animation_glb, clip_frame_glb
from pdeanim.gltf.validate import assert_clean, validate_many


def test_parts_follow_the_clip_contract(trout_parts):
    th, ta = container.unpack(trout_parts.topology)
    ch, ca = container.unpack(trout_parts.coefficients)
    assert th["part"] == "topology" and ch["part"] == "coefficients"
    assert ch["kind"] == "cyclic-spine" and ch["topology_id"] == trout_parts.topology_id
    assert {"faces", "rest", "vertex_patch", "vertex_uv", "vertex_offset", "curves"} <= ta.keys()
    assert ca["spine"].shape == (12, 4, 3)
    assert len(trout_parts.coefficients) < 2000


def test_clip_protocol_and_rest_pose(trout_clip, trout_mesh):
    assert isinstance(trout_clip, Clip)
    assert trout_clip.looping and trout_clip.kind == "cyclic-spine"
    assert trout_clip.n_vertices == len(trout_mesh.vertices)
    assert np.array_equal(trout_clip.faces, trout_mesh.faces.astype(np.int32))
    rest = trout_clip.evaluate(0.0)
    assert rest.dtype == np.float32 and rest.shape == (trout_clip.n_vertices, 3)
    assert np.array_equal(rest, trout_mesh.vertices.astype(np.float32))
    info = trout_clip.info()
    assert info["frames"] == 25 and info["looping"] and info["period"] == pytest.approx(0.5)
    assert trout_clip.frame_times[-1] == pytest.approx(0.5)


def test_loop_and_vectorised_evaluation(trout_clip):
    t = np.linspace(0.0, 1.0, 25)
    frames = trout_clip.evaluate(t)
    assert frames.shape == (25, trout_clip.n_vertices, 3) and frames.dtype == np.float32
    assert np.abs(frames[-1] - frames[0]).max() < 1e-6
    assert np.array_equal(frames[7], trout_clip.evaluate(float(t[7])))
    shifted = trout_clip.evaluate(t + 3.0)
    assert np.abs(shifted - frames).max() < 1e-6
    period = trout_clip.params.period
    assert np.abs(trout_clip.evaluate_seconds(0.3) - trout_clip.evaluate_seconds(0.3 + period)).max() < 1e-6
    assert np.abs(frames - frames[0]).max() > 0.05  # it does swim (trout: 8% of the length at the tail)


def test_file_round_trip(tmp_path, trout_parts, trout_clip):
    path = tmp_path / "trout.clip"
    write_clip_file(path, trout_parts)
    again = read_clip_file(path)
    clip = load_clip(again.topology, again.coefficients)
    assert np.array_equal(clip.evaluate([0.1, 0.6]), trout_clip.evaluate([0.1, 0.6]))


def test_broken_parts_raise(trout_parts):
    th, ta = container.unpack(trout_parts.topology)
    ch, ca = container.unpack(trout_parts.coefficients)
    with pytest.raises(ClipFormatError):
        clip_from_parts(th, {k: v for k, v in ta.items() if k != "rest"}, ch, ca)
    with pytest.raises(ClipFormatError):
        clip_from_parts(th, ta, {**ch, "swim": {"mode": "eel", "frequency": -1}}, ca)
    with pytest.raises(ClipFormatError):
        clip_from_parts(th, ta, ch, {"spine": ca["spine"][:2]})
    other = container.pack({**th, "producer": "x"}, ta)
    with pytest.raises(ClipFormatError):
        load_clip(other, trout_parts.coefficients)  # topology_id mismatch
    parts = ClipParts(trout_parts.topology, trout_parts.coefficients)
    assert parts.topology_id == ch["topology_id"] == hashlib.sha256(trout_parts.topology).hexdigest()
    sizes = parts.sizes(n_frames=25, n_vertices=len(ta["rest"]))
    assert sizes["raw_float32_bytes"] == 25 * len(ta["rest"]) * 12
    assert sizes["ratio_total_to_raw"] == pytest.approx(
        (len(trout_parts.topology) + len(trout_parts.coefficients)) / sizes["raw_float32_bytes"])


def test_looping_glb_is_valid(trout_clip):
    glb = clip_animation_glb(trout_clip, fps=30)
    frame = clip_frame_glb(trout_clip, 0.37)
    for report, label in zip(validate_many([glb, frame]), ("animation", "frame"), strict=True):
        assert_clean(report, label)


def test_pde_surface_representation_moves_with_the_mesh(trout_clip):
    rest_grid, faces = trout_clip.surface_frames(0.0, n_s=37, n_v=32)
    assert rest_grid.shape == (1, 37 * 32, 3) and faces.max() < 37 * 32
    assert np.abs(rest_grid[0].reshape(37, 32, 3) - trout_clip.curves).max() < 1e-5  # grid rows = curves
    moved, _ = trout_clip.surface_frames(np.array([0.25, 1.25]), n_s=37, n_v=32)
    assert np.abs(moved[0] - moved[1]).max() < 1e-6
    grid_shift = (moved[0] - rest_grid[0]).reshape(37, 32, 3).mean(axis=1) @ trout_clip.frame.lateral
    s = np.linspace(0, 1, 37)
    mesh_shift = (trout_clip.evaluate(0.25) - trout_clip.rest) @ trout_clip.frame.lateral
    near = np.abs(trout_clip.s[:, None] - s[None]).argmin(axis=0)
    assert np.abs(grid_shift - mesh_shift[near]).max() < 0.01  # both follow the same spine wave
