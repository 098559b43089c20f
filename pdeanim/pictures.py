"""Pictures of fit errors (matplotlib, Agg canvas, no global pyplot state): the mesh coloured by per-vertex
error seen from two sides along its principal axes, and RMS / max error per frame over time."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from .errors import ParameterError  # noqa: E402

MAX_FACES = 20_000  # larger meshes are simplified by vertex clustering before drawing (said in the picture)
_LIGHT = np.array([0.3, 0.4, 0.87])


def principal_frame(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and rows of principal axes (3, 3), largest spread first, signs fixed deterministically."""
    v = np.asarray(vertices, np.float64)
    centre = v.mean(axis=0)
    _, _, vt = np.linalg.svd(v - centre, full_matrices=False)
    axes = np.zeros((3, 3))
    axes[: len(vt)] = vt
    if len(vt) < 3 or not np.isfinite(axes).all():
        axes = np.eye(3)
    axes *= np.where(axes[np.arange(3), np.abs(axes).argmax(axis=1)] < 0, -1.0, 1.0)[:, None]
    axes[2] = np.cross(axes[0], axes[1])  # right-handed
    return centre, axes


def _check(vertices: np.ndarray, faces: np.ndarray | None, error: np.ndarray) -> tuple[np.ndarray, ...]:
    v = np.asarray(vertices, np.float64)
    f = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, np.int64).reshape(-1, 3)
    e = np.asarray(error, np.float64).reshape(-1)
    if v.ndim != 2 or v.shape[1] != 3 or e.shape != (len(v),):
        raise ParameterError(f"need vertices (V, 3) and per-vertex errors (V,), got {v.shape} and {e.shape}")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ParameterError("face indices out of range")
    if not (np.isfinite(v).all() and np.isfinite(e).all()):
        raise ParameterError("vertices and errors must be finite")
    return v, f, e


def view_rotation(across: int, up: int, depth: int) -> np.ndarray:
    """Rotation (3, 3) from principal coordinates to plot coordinates (x = across, y = depth away from the
    camera, z = up); the depth sign is chosen so the picture is not mirrored."""
    r = np.eye(3)[[across, depth, up]]
    if np.linalg.det(r) < 0:
        r[1] *= -1
    return r


def _pick_faces(plot: np.ndarray, limit: int) -> tuple[np.ndarray, bool]:
    """Faces of (T, 3, 3) plot-space triangles that face the camera (normal toward -y), subsampled evenly to
    ``limit``; hidden faces are dropped first, so the limit goes to what can be seen."""
    n = np.cross(plot[:, 1] - plot[:, 0], plot[:, 2] - plot[:, 0])
    front = np.flatnonzero(n[:, 1] < 0)
    keep = front if len(front) > 0.2 * len(plot) else np.arange(len(plot))  # open or flipped meshes: all
    if len(keep) <= limit:
        return keep, False
    return keep[np.linspace(0, len(keep) - 1, limit).astype(np.int64)], True


def _draw_view(fig: Figure, rect: list[float], tris: np.ndarray, face_err: np.ndarray, norm: Normalize,
               rot: np.ndarray, label: str) -> bool:
    """One orthographic view of principal-frame triangles (T, 3, 3) rotated by ``rot`` into plot space."""
    ax = fig.add_axes(rect, projection="3d")
    plot_all = tris @ rot.T
    keep, sub = _pick_faces(plot_all, MAX_FACES)
    plot = plot_all[keep]
    n = np.cross(plot[:, 1] - plot[:, 0], plot[:, 2] - plot[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    shade = 0.5 + 0.5 * np.abs(n @ (_LIGHT / np.linalg.norm(_LIGHT)))
    rgba = colormaps["inferno"](norm(face_err[keep]))
    rgba[:, :3] *= shade[:, None]
    ax.add_collection3d(Poly3DCollection(plot, facecolors=rgba, edgecolors=rgba, linewidths=0.2))
    pts = plot_all.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ext = np.maximum(hi - lo, 1e-3 * max(float((hi - lo).max()), 1e-30))
    ax.set_xlim(lo[0], lo[0] + ext[0])
    ax.set_ylim(lo[1], lo[1] + ext[1])
    ax.set_zlim(lo[2], lo[2] + ext[2])
    ax.set_proj_type("ortho")
    ax.set_box_aspect(tuple(ext / ext.max()), zoom=1.12)
    ax.view_init(elev=0, azim=-90)  # camera on -y looking along +y
    ax.set_axis_off()
    ax.text2D(0.5, 0.98, label, transform=ax.transAxes, ha="center", va="top", fontsize=9)
    return sub


def simplify_for_picture(vertices: np.ndarray, faces: np.ndarray, error: np.ndarray,
                         limit: int = MAX_FACES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex clustering on a uniform grid until at most ``limit`` faces remain: vertices (V', 3) at cluster
    means, faces (T', 3) without degenerate or repeated triangles, error (V',) = max error in each cluster
    (so hot spots stay visible). Returns the input unchanged when it is already small enough."""
    if len(faces) <= limit:
        return vertices, faces, error
    lo = vertices.min(axis=0)
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    h = max(np.sqrt(2.0 * area / limit), 1e-12 * float(np.ptp(vertices, axis=0).max()) + 1e-300)
    while True:
        cells = np.floor((vertices - lo) / h).astype(np.int64)
        _, cluster = np.unique(cells, axis=0, return_inverse=True)
        cluster = cluster.reshape(-1)
        cf = cluster[faces]
        cf = cf[(cf[:, 0] != cf[:, 1]) & (cf[:, 1] != cf[:, 2]) & (cf[:, 0] != cf[:, 2])]
        _, first = np.unique(np.sort(cf, axis=1), axis=0, return_index=True)
        cf = cf[np.sort(first)]
        if len(cf) <= limit:
            break
        h *= 1.25
    n = int(cluster.max()) + 1
    count = np.bincount(cluster, minlength=n)[:, None]
    verts = np.stack([np.bincount(cluster, vertices[:, c], n) for c in range(3)], axis=1) / np.maximum(
        count, 1
    )
    err = np.full(n, -np.inf)
    np.maximum.at(err, cluster, error)
    return verts, cf, err


def error_png(vertices: np.ndarray, faces: np.ndarray | None, per_vertex_error: np.ndarray, path: str | Path,
              title: str, units: str = "mesh units", diagonal: float | None = None) -> Path:
    """Render the mesh (V, 3) with faces (T, 3) coloured by per-vertex error (V,) (face colour = mean of its
    vertices), seen along its 3rd and 2nd principal axes, with a colour bar in ``units``; writes a PNG.
    Relative errors use ``diagonal`` (the rest pose's bbox diagonal) or else this mesh's own."""
    v, f, e = _check(vertices, faces, per_vertex_error)
    if not len(f):
        raise ParameterError("error_png needs faces (point data cannot be rendered as a surface)")
    centre, axes = principal_frame(v)
    sv, sf, se = simplify_for_picture((v - centre) @ axes.T, f, e)
    tris, face_err = sv[sf], se[sf].mean(axis=1)
    norm = Normalize(0.0, max(float(e.max()), 1e-30))
    fig = Figure(figsize=(10, 4.4), dpi=110)
    FigureCanvasAgg(fig)
    sub = _draw_view(fig, [0.0, 0.02, 0.45, 0.8], tris, face_err, norm, view_rotation(0, 1, 2),
                     "view along principal axis 3")
    sub |= _draw_view(fig, [0.44, 0.02, 0.45, 0.8], tris, face_err, norm, view_rotation(0, 2, 1),
                      "view along principal axis 2")
    sm = matplotlib.cm.ScalarMappable(norm=norm, cmap="inferno")
    bar = fig.colorbar(sm, cax=fig.add_axes([0.91, 0.12, 0.018, 0.64]))
    bar.set_label(f"error ({units})")
    diag = float(np.linalg.norm(np.ptp(v, axis=0))) if diagonal is None else float(diagonal)
    rel = f" ({e.max() / diag:.2%} of the bbox diagonal)" if diag > 0 else ""
    note = f"max {e.max():.3g}{rel}, mean {e.mean():.3g} {units}; {len(v)} vertices, {len(f)} faces"
    if len(sf) < len(f):
        note += f"; drawn simplified to {len(sf)} faces (colour: max error per cluster)"
    if sub:
        note += f"; faces subsampled to {MAX_FACES} per view"
    fig.suptitle(f"{title}\n{note}", fontsize=10)
    path = Path(path)
    fig.savefig(path, format="png", metadata={"Title": title, "Description": note})  # readable without OCR
    return path


def error_curve_png(per_frame_rms: np.ndarray, per_frame_max: np.ndarray, times: np.ndarray, path: str | Path,
                    title: str = "fit error per frame", units: str = "mesh units",
                    diagonal: float | None = None) -> Path:
    """Plot RMS and max error per frame (F,) against times (F,) seconds, the worst frame marked (and the
    errors relative to ``diagonal`` when given, the rest pose's bounding-box diagonal); writes a PNG."""
    rms, mx, t = (np.asarray(a, np.float64).reshape(-1) for a in (per_frame_rms, per_frame_max, times))
    if not (rms.shape == mx.shape == t.shape) or not len(t):
        raise ParameterError(f"need equal-length rms, max and times, got {rms.shape}, {mx.shape}, {t.shape}")
    if not (np.isfinite(rms).all() and np.isfinite(mx).all() and np.isfinite(t).all()):
        raise ParameterError("errors and times must be finite")
    fig = Figure(figsize=(8, 3.6), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(t, mx, color="#c0392b", lw=1.4, label="max")
    ax.plot(t, rms, color="#2c3e50", lw=1.4, label="RMS")
    worst = int(mx.argmax())
    ax.axvline(t[worst], color="#c0392b", lw=0.8, ls=":")
    right = t[worst] > (t[0] + t[-1]) / 2  # keep the label inside the axes
    ax.annotate(
        f"worst frame {worst}\nmax {mx[worst]:.3g}",
        (t[worst], mx[worst]),
        textcoords="offset points",
        xytext=(-10 if right else 10, -30),
        ha="right" if right else "left",
        fontsize=8,
        color="#c0392b",
        bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "#c0392b", "alpha": 0.9},
    )
    if rms.min() > 0 and mx.max() / rms.min() > 50:
        ax.set_yscale("log")
    else:
        ax.set_ylim(0, mx.max() * 1.15 if mx.max() > 0 else 1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"error ({units})")
    rel = (f"\nrelative to the bbox diagonal: RMS mean {rms.mean() / diagonal:.2e}, "
           f"max {mx.max() / diagonal:.2e}" if diagonal else "")
    ax.set_title(f"{title}: RMS mean {rms.mean():.3g}, max {mx.max():.3g} {units}{rel}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left" if right else "upper right", fontsize=8, framealpha=0.9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, format="png", metadata={"Title": title, "Description": f"worst frame {worst}"})
    return path


def fit_error_pictures(reference: np.ndarray, fitted: np.ndarray, faces: np.ndarray, times: np.ndarray,
                       out_dir: str | Path, name: str = "fit") -> dict[str, Path]:
    """Both pictures for a fit: reference and fitted frames (F, V, 3); the mesh picture shows the frame with
    the largest max error. Returns {"worst_frame": path, "error_curve": path}."""
    ref, fit = np.asarray(reference, np.float64), np.asarray(fitted, np.float64)
    if ref.shape != fit.shape or ref.ndim != 3:
        raise ParameterError(f"reference and fitted must both be (F, V, 3), got {ref.shape} and {fit.shape}")
    err = np.linalg.norm(fit - ref, axis=-1)  # (F, V)
    rms, mx = np.sqrt((err**2).mean(axis=1)), err.max(axis=1)
    worst = int(mx.argmax())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    diagonal = float(np.linalg.norm(np.ptp(ref[0], axis=0)))  # the first frame's, as in the fit report
    return {"worst_frame": error_png(ref[worst], faces, err[worst], out / f"{name}_worst_frame.png",
                                     f"{name}: per-vertex error at frame {worst} (t = {times[worst]:.3f} s)",
                                     diagonal=diagonal),
            "error_curve": error_curve_png(rms, mx, times, out / f"{name}_error_curve.png", f"{name} error",
                                           diagonal=diagonal)}
