"""Cutting elongated meshes into cross-section curves, and the clear errors when that is impossible."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pdeanim.cyclic.body import body_frame, chain_segments, cut_body, resample_loop
from pdeanim.cyclic.chain import BodySurface, valid_curve_count
from pdeanim.errors import InputError


def test_frame_of_trout_points_head_to_tail(trout_mesh):
    frame = body_frame(trout_mesh.vertices)
    assert np.allclose(frame.axis, [1, 0, 0], atol=1e-6)  # head (thick end) at x = 0
    assert abs(frame.lateral @ [0, 0, 1]) > 0.999  # the narrow direction is sideways
    assert np.allclose(np.cross(frame.axis, frame.lateral), frame.up)
    assert frame.length == pytest.approx(1.0, rel=1e-6)


def test_head_and_tail_points_set_the_axis(trout_mesh):
    flipped = body_frame(trout_mesh.vertices, head=[1.0, 0, 0])
    assert np.allclose(flipped.axis, [-1, 0, 0], atol=1e-6)
    both = body_frame(trout_mesh.vertices, head=[0, 0, 0], tail=[1, 0.1, 0], lateral=[0, 0, 1])
    assert both.axis @ np.array([1, 0.1, 0]) / np.hypot(1, 0.1) == pytest.approx(1.0)
    assert abs(both.lateral @ [0, 0, 1]) > 0.999


def test_curves_are_consistent_loops(trout_mesh):
    frame = body_frame(trout_mesh.vertices)
    body = cut_body(trout_mesh.vertices, trout_mesh.faces, frame, 37, 32)
    assert body.curves.shape == (37, 32, 3)
    assert (body.loops == 1).all()
    local = frame.to_local(body.curves.reshape(-1, 3)).reshape(37, 32, 3)
    inner = local[1:-1]
    assert np.ptp(inner[..., 0], axis=1).max() < 1e-7  # each curve lies in its plane (up to joined ends)
    centred = inner[..., 1:] - inner[..., 1:].mean(axis=1, keepdims=True)
    assert (centred[:, 0, 0] > 0).all() and (np.abs(centred[:, 0, 1]) < 1e-3).all()  # start on +lateral
    ang = np.unwrap(np.arctan2(centred[..., 1], centred[..., 0]), axis=1)
    assert (np.diff(ang, axis=1) > 0).all()  # counter-clockwise about the axis
    step = np.linalg.norm(np.diff(inner, axis=1), axis=2)
    assert (step.max(axis=1) / step.min(axis=1)).max() < 1.6  # roughly equal arc length
    assert np.ptp(body.curves[0], axis=0).max() == 0 and np.ptp(body.curves[-1], axis=0).max() == 0  # tips


def test_chain_shares_curves_and_reproduces_them(capsule_mesh):
    frame = body_frame(capsule_mesh.vertices)
    body = cut_body(capsule_mesh.vertices, capsule_mesh.faces, frame, valid_curve_count(20), 24)
    surface = BodySurface.from_curves(body.curves)
    assert len(body.curves) == 22 and surface.n_patches == 7
    v = np.arange(24) * (2 * np.pi / 24)
    for k, s in enumerate(surface.curve_s()):
        assert np.abs(surface.evaluate(np.full(24, s), v) - body.curves[k]).max() < 1e-9
    mid = surface.evaluate(np.full(24, 0.5), v)
    radius = np.linalg.norm(frame.to_local(mid)[:, 1:], axis=1)
    assert np.abs(radius - 0.5).max() < 0.01  # the capsule's cylinder


def test_chain_segments_joins_a_square():
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    segs = np.stack([sq, np.roll(sq, -1, axis=0)], axis=1)[[2, 0, 3, 1]]
    loops, chains = chain_segments(segs, 1e-9)
    assert len(loops) == 1 and not chains and len(loops[0]) == 4
    loops, chains = chain_segments(segs[:3], 1e-9)
    assert not loops and len(chains) == 1 and len(chains[0]) == 4


def test_resample_reverses_clockwise_loops(trout_mesh):
    frame = body_frame(trout_mesh.vertices)
    th = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    loop = frame.origin + np.outer(np.cos(th), frame.lateral) + np.outer(np.sin(th), frame.up)
    a = resample_loop(loop, frame, 16)
    b = resample_loop(loop[::-1], frame, 16)
    assert np.abs(a - b).max() < 1e-2


def test_not_elongated_is_an_input_error():
    sphere = trimesh.creation.icosphere(3)
    with pytest.raises(InputError, match="not elongated"):
        body_frame(sphere.vertices)


def test_no_faces_is_an_input_error(capsule_mesh):
    frame = body_frame(capsule_mesh.vertices)
    with pytest.raises(InputError, match="no triangle faces"):
        cut_body(capsule_mesh.vertices, np.zeros((0, 3), int), frame, 10, 16)


def test_two_separate_bodies_are_an_input_error(capsule_mesh):
    twin = trimesh.util.concatenate(
        [
            trimesh.Trimesh(capsule_mesh.vertices, capsule_mesh.faces),
            trimesh.Trimesh(capsule_mesh.vertices + [0, 0, 2.0], capsule_mesh.faces),
        ]
    )
    frame = body_frame(twin.vertices)
    with pytest.raises(InputError, match="several separate loops"):
        cut_body(twin.vertices, twin.faces, frame, 10, 16)


def test_gap_along_the_axis_is_an_input_error(capsule_mesh):
    far = trimesh.util.concatenate([trimesh.Trimesh(capsule_mesh.vertices, capsule_mesh.faces),
                                    trimesh.Trimesh(capsule_mesh.vertices + [6.0, 0, 0], capsule_mesh.faces)])
    frame = body_frame(far.vertices)
    with pytest.raises(InputError, match="empty"):
        cut_body(far.vertices, far.faces, frame, 37, 16)
