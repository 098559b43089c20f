"""Clip export to GLB: the CLI and the library functions, on an analytic clip (the Clip protocol) and on a
real looping cyclic clip file; every output validator-clean, loops seamless, frames as evaluated."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pdeanim import fit as fitclip
from pdeanim.cli import main
from pdeanim.clip import Clip, load_clip, write_clip_file
from pdeanim.cyclic import job
from pdeanim.errors import LimitError, ParameterError
from pdeanim.gltf.clipexport import (
    QUANT_SHARE,
    clip_animation_glb,
    clip_frame_glb,
    export_position_error,
    export_times,
)
from pdeanim.gltf.compact import PackOptions
from pdeanim.gltf.glb import unpack_glb
from pdeanim.gltf.read import read_animated_poses
from pdeanim.gltf.validate import assert_clean, validate_many
from pdeanim.gltf.write import animation_glb
from pdeanim.pictures import fit_error_pictures

from .builders import clip_vertices


class WaveClip:
    """A bar-shaped analytic clip: vertices wave in z with one cycle over t in [0, 1]."""

    kind = "test-wave"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, looping: bool, seconds: float = 1.3) -> None:
        self.rest, self.faces, self.looping = vertices.astype(np.float32), faces.astype(np.int32), looping
        self.n_vertices = len(vertices)
        self.frame_times = np.linspace(0.0, seconds, 40)

    def evaluate(self, t):
        tt = np.atleast_1d(np.asarray(t, np.float64))
        z = 0.1 * np.sin(2 * np.pi * (tt[:, None] + self.rest[None, :, 0]))
        out = np.repeat(self.rest[None], len(tt), axis=0)
        out[..., 2] += z.astype(np.float32)
        return out[0] if np.ndim(t) == 0 else out

    def info(self):
        return {"kind": self.kind}


@pytest.fixture
def wave(spot):
    v, f = spot
    return WaveClip(v, f, looping=True)


def test_wave_clip_is_a_clip(wave):
    assert isinstance(wave, Clip)


def test_export_samples_with_last_frame_and_loops_seamlessly(wave):
    glb = clip_animation_glb(wave, fps=10)
    poses = read_animated_poses(glb, fps=10)
    seconds = export_times(1.3, 10)
    np.testing.assert_allclose(seconds, np.arange(14) / 10)  # 1.3 s lies on the grid
    np.testing.assert_allclose(export_times(1.25, 10), [*np.arange(13) / 10, 1.25])  # off-grid end appended
    assert poses.n_frames == len(seconds)
    want = wave.evaluate(seconds / 1.3)
    shown = clip_vertices(glb)  # spot's UV seams weld: one written vertex for the clip's twins
    assert len(shown) < wave.n_vertices and set(shown) <= set(range(wave.n_vertices))
    step = float(np.ptp(want.reshape(-1, 3), axis=0).max()) / (2**14 - 1)  # no stored error: 14 bits
    np.testing.assert_allclose(poses.vertices[:-1], want[:-1, shown], atol=step)  # half a step, 2x margin
    np.testing.assert_array_equal(poses.vertices[-1], poses.vertices[0])  # seamless wrap
    once = WaveClip(wave.rest, wave.faces, looping=False)
    plain = PackOptions(quantize=False, compress=False, weld=False)
    p2 = read_animated_poses(clip_animation_glb(once, fps=10, options=plain), fps=10)
    np.testing.assert_allclose(p2.vertices, once.evaluate(seconds / 1.3), atol=1e-6)  # float32 storage
    welded = clip_animation_glb(once, fps=10, options=PackOptions(quantize=False))
    p3 = read_animated_poses(welded, fps=10)
    np.testing.assert_allclose(p3.vertices, p2.vertices[:, clip_vertices(welded)], atol=1e-6)  # lossless


def test_frame_and_bad_parameters(wave):
    with pytest.raises(ParameterError):
        clip_animation_glb(wave, fps=0)
    with pytest.raises(LimitError):
        clip_animation_glb(wave, fps=1e6)
    with pytest.raises(ParameterError):
        clip_frame_glb(wave, float("nan"))
    reports = validate_many([clip_frame_glb(wave, 0.37), clip_animation_glb(wave, 8)])
    for label, report in zip(["frame", "quantised animation"], reports, strict=True):
        assert_clean(report, label)


def test_cli_export_of_a_real_cyclic_clip(data_dir, tmp_path, capsys):
    mesh = trimesh.load(data_dir / "fish_capsule.obj", process=False)
    parts = job.make_cyclic_clip(mesh, job.CyclicOptions.from_dict({"mode": "eel", "frames": 12}))
    clip_path, out = tmp_path / "swim.clip", tmp_path / "swim.glb"
    write_clip_file(clip_path, parts)
    assert main(["export", str(clip_path), "--fps", "12", "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    glb = out.read_bytes()
    assert_clean(validate_many([glb])[0], "cyclic export")
    poses = read_animated_poses(glb, fps=12)
    np.testing.assert_array_equal(poses.vertices[-1], poses.vertices[0])
    assert main(["export", str(tmp_path / "missing.clip"), "--out", str(out)]) == 2


class ErrorWave(WaveClip):
    """The wave clip stating an RMS fit error, as a fitted clip's header does."""

    def __init__(self, *args, rms: float, **kw) -> None:
        super().__init__(*args, **kw)
        self.rms = rms

    def info(self):
        return {"kind": self.kind, "errors": {"rms": self.rms}}


@pytest.mark.parametrize("rms", [1e-3, 4e-3])
def test_default_grid_follows_the_clips_own_error(spot, rms):
    """The default export's grid step is 2 x QUANT_SHARE x the clip's RMS error (its rounding adds that share
    of it in RMS), every vertex within step x sqrt(3) / 2; position_bits sets the grid by hand instead."""
    v, f = spot
    clip = ErrorWave(v, f, looping=False, rms=rms)
    assert export_position_error(clip) == QUANT_SHARE * rms
    glb = clip_animation_glb(clip, fps=10)
    doc, _ = unpack_glb(glb)
    (scale,) = {n["scale"][0] for n in doc["nodes"] if "scale" in n}
    assert scale == pytest.approx(2 * QUANT_SHARE * rms, rel=1e-6)
    poses = read_animated_poses(glb, fps=10)
    want = clip.evaluate(export_times(1.3, 10) / 1.3)[:, clip_vertices(glb)]
    d = np.linalg.norm(poses.vertices - want, axis=-1)
    assert d.max() <= scale * np.sqrt(3) / 2 * 1.01
    assert 0.5 * QUANT_SHARE * rms < np.sqrt(np.mean(d * d)) <= 1.1 * QUANT_SHARE * rms  # measured 0.99-1.0
    fine = clip_animation_glb(clip, fps=10, options=PackOptions(normals=False, position_bits=14))
    assert len(fine) > len(glb)
    assert export_position_error(WaveClip(v, f, looping=False)) is None  # no stored error: 14 bits


def test_glb_in_fit_glb_out_with_pictures(morph, tmp_path):
    """End to end through the model's fit: animated GLB -> poses -> dynamic-PDE clip -> validator-clean GLB,
    and the error pictures of the fit."""
    frames, faces, times = morph
    poses = read_animated_poses(animation_glb(frames[:30], times[:30], faces), fps=30)
    parts = fitclip.fit_poses(poses, fitclip.FitOptions.from_dict({"target_rel_rms": 1e-2}))
    clip = load_clip(parts.topology, parts.coefficients)
    glb = clip_animation_glb(clip, 30)
    assert_clean(validate_many([glb])[0], "fitted clip export")
    welded = read_animated_poses(glb, fps=30)
    assert welded.n_frames == 30
    unwelded = PackOptions(weld=False, position_bits=None)  # the default grid (from the clip's error)
    back = read_animated_poses(clip_animation_glb(clip, 30, options=unwelded), fps=30)
    shown = clip_vertices(glb)  # the sphere's seam welds: its twins are written once
    assert len(shown) < poses.vertices.shape[1] and len(np.unique(shown)) == len(shown)
    np.testing.assert_array_equal(welded.vertices, back.vertices[:, shown])  # the same grid values
    diag = float(np.linalg.norm(np.ptp(frames[0], axis=0)))
    rms = float(np.sqrt(((back.vertices - poses.vertices) ** 2).sum(axis=-1).mean()))
    # the fit achieves rel RMS 1.8e-3 (target 1e-2); the export's grid adds QUANT_SHARE of it in quadrature
    # (sqrt(1 + 0.25^2) = 1.03 times the fit's RMS in all)
    assert parts.report["rel_rms"] < 1e-2
    assert 0.99 < rms / diag / parts.report["rel_rms"] < 1 + 2 * (np.hypot(1, QUANT_SHARE) - 1)
    paths = fit_error_pictures(poses.vertices, back.vertices, faces, poses.times, tmp_path, "sphere")
    assert all(p.stat().st_size > 10_000 for p in paths.values())


def test_cli_export_keeps_the_look_of_a_gltf_source(tmp_path, capsys):
    """A clip fitted on poses of a textured glTF, exported with ``--mesh``: the GLB has the source's
    materials, texture and node names; options are checked (exit 2 with a message)."""
    from pdeanim.gltf.glb import unpack_glb
    from pdeanim.gltf.read import read_static_mesh
    from pdeanim.poses import make_poses

    from .builders import textured_scene_glb

    src = textured_scene_glb()
    rest, faces = read_static_mesh(src)
    frames = rest[None] + 0.1 * np.sin(np.arange(10)[:, None, None] / 3 + rest[None, :, :1])
    parts = fitclip.fit_poses(make_poses(frames, faces, np.arange(10) / 30.0, {}),
                              fitclip.FitOptions.from_dict({"segments": 1}))
    clip_path, mesh_path, out = tmp_path / "scene.clip", tmp_path / "scene.glb", tmp_path / "anim.glb"
    write_clip_file(clip_path, parts)
    mesh_path.write_bytes(src)
    assert main(["export", str(clip_path), "--mesh", str(mesh_path), "--out", str(out), "--fps", "30"]) == 0
    assert "look of gltf source" in capsys.readouterr().out
    doc, _ = unpack_glb(out.read_bytes())
    assert [m["name"] for m in doc["materials"]] == ["skin", "cloth"]
    assert doc["images"][0]["name"] == "checker"
    assert [n.get("name") for n in doc["nodes"][:3]] == ["body", "hat", "wing"]
    assert_clean(validate_many([out.read_bytes()])[0], "CLI export with --mesh")
    assert read_animated_poses(out.read_bytes(), fps=30).n_frames == 10
    assert main(["export", str(clip_path), "--mesh", str(tmp_path / "missing.glb"), "--out", str(out)]) == 2
    assert main(["export", str(clip_path), "--position-bits", "20", "--out", str(out)]) == 2
    assert "position_bits" in capsys.readouterr().err


def test_exports_leave_normal_targets_out_unless_asked(wave, tmp_path):
    """The default export carries the base normals only (no per-frame normal targets, 35-40% of a smooth
    mesh's GLB); ``normals=True``, the export job's ``normals`` and ``--normal-targets`` keep them."""
    from pdeanim.gltf.clipexport import ExportOptions
    from pdeanim.gltf.glb import unpack_glb

    def normal_targets(glb: bytes) -> tuple[bool, bool]:
        doc, _ = unpack_glb(glb)
        prims = [p for m in doc["meshes"] for p in m["primitives"]]
        return (all("NORMAL" in p["attributes"] for p in prims),
                any("NORMAL" in t for p in prims for t in p.get("targets", [])))

    default = clip_animation_glb(wave, fps=10)
    kept = clip_animation_glb(wave, fps=10, options=PackOptions(normals=True))
    assert normal_targets(default) == (True, False) and normal_targets(kept) == (True, True)
    assert len(default) < 0.8 * len(kept)
    assert ExportOptions.from_dict({}).normals is False and ExportOptions.from_dict({"normals": True}).normals
    clip_path = tmp_path / "wave.clip"
    from pdeanim.poses import make_poses

    frames = wave.evaluate(np.linspace(0, 1, 12))
    parts = fitclip.fit_poses(make_poses(frames, wave.faces, np.arange(12) / 10.0, {}),
                              fitclip.FitOptions.from_dict({"segments": 1}))
    write_clip_file(clip_path, parts)
    for flags, want in (([], False), (["--normal-targets"], True), (["--no-normal-targets"], False)):
        out = tmp_path / f"wave{len(flags)}{want}.glb"
        assert main(["export", str(clip_path), "--out", str(out), "--fps", "10", "-q", *flags]) == 0
        assert normal_targets(out.read_bytes()) == (True, want), flags
