"""PNG pictures of a body, its PDE spine and its swim cycle (matplotlib with the Agg backend).

Views are orthographic projections on the body axes: "top" looks down the up axis (axis x lateral plane,
where the swim wave shows), "side" looks along the lateral axis (axis x up plane).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from .body import BodyFrame  # noqa: E402

VIEWS = {"top": (0, 1), "side": (0, 2)}
"""Which two body coordinates (axial 0, lateral 1, up 2) each view shows."""


def _draw_mesh(
    ax: plt.Axes, local: np.ndarray, faces: np.ndarray, view: str, color: str, shift: float = 0.0
) -> None:
    """Fill the projected triangles of a mesh (local (V, 3) body coordinates), shaded by facing."""
    i, j = VIEWS[view]
    tri = local[faces]  # (T, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    depth = 3 - i - j
    order = np.argsort(tri[:, :, depth].mean(axis=1))
    shade = 0.45 + 0.55 * np.abs(normal[:, depth]) / (np.linalg.norm(normal, axis=1) + 1e-30)
    polys = tri[order][:, :, [i, j]] + np.array([0.0, shift])
    base = np.array(matplotlib.colors.to_rgb(color))
    ax.add_collection(PolyCollection(polys, facecolors=shade[order, None] * base, edgecolors="none"))


def plot_body_spine(path: str | Path, vertices: np.ndarray, faces: np.ndarray, frame: BodyFrame,
                    spine: np.ndarray, curves: np.ndarray | None = None) -> Path:
    """Top and side views of a mesh with its spine polyline (n, 3) and optional boundary curves (K, P, 3)."""
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), dpi=110)
    local, sp = frame.to_local(vertices), frame.to_local(spine)
    for ax, view in zip(axes, VIEWS, strict=True):
        i, j = VIEWS[view]
        _draw_mesh(ax, local, np.asarray(faces), view, "#7fa7c9")
        if curves is not None:
            for c in curves:
                cl = frame.to_local(c)
                ax.plot(np.append(cl[:, i], cl[0, i]), np.append(cl[:, j], cl[0, j]), color="#555", lw=0.5)
        ax.plot(sp[:, i], sp[:, j], color="#d62728", lw=2, label="spine A0(u)")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(f"{view} view")
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def plot_swim_frames(path: str | Path, clip: object, times: np.ndarray, view: str = "top",
                     surface: bool = False) -> Path:
    """Frames of a CyclicClip at clip times (K,), stacked one above the other, each with its moving spine;
    surface=True draws the PDE-surface representation instead of the mesh."""
    times = np.asarray(times, dtype=np.float64)
    if surface:
        frames, faces = clip.surface_frames(times)
    else:
        frames, faces = clip.evaluate(times), clip.faces
    frame = clip.frame
    gap = 1.6 * max(np.ptp(frame.to_local(clip.rest)[:, VIEWS[view][1]]), 0.25 * frame.length)
    fig, ax = plt.subplots(figsize=(7, 1.2 + 1.1 * len(times)), dpi=110)
    i, j = VIEWS[view]
    for k, t in enumerate(times):
        shift = -k * gap
        _draw_mesh(ax, frame.to_local(frames[k]), faces, view, "#c9a227" if surface else "#6a9f58", shift)
        sp = frame.to_local(clip.spine_at(float(t)))
        ax.plot(sp[:, i], sp[:, j] + shift, color="#d62728", lw=1.5)
        ax.text(frame.x_min - 0.05 * frame.length, shift, f"t={t:.3f}", ha="right", va="center", fontsize=8)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlim(frame.x_min - 0.25 * frame.length, frame.x_max + 0.05 * frame.length)
    what = "PDE surface" if surface else "mesh"
    ax.set_title(f"{clip.params.mode} swim cycle of the {what}, {view} view (head left)")
    ax.axis("off")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
