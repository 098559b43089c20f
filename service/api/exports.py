"""GLB outputs of clips in the API process: the source mesh's layout (loaded once per cached clip, lazily),
a frame writer that keeps the source's look, and the synchronous-export limits (fps, size estimate)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from ..settings import Settings
from .errors import ApiError


class LazyLayout:
    """The :class:`pdeanim.gltf.layout.Layout` of a clip's source mesh, built on first use (thread-safe)."""

    def __init__(self, load: Callable[[], Any]) -> None:
        self._load, self._value, self._lock = load, None, threading.Lock()

    @property
    def loaded(self) -> bool:
        """Whether the layout is built (get() costs no I/O)."""
        return self._value is not None

    def get(self) -> Any:
        """The layout (built once)."""
        with self._lock:
            if self._value is None:
                self._value = self._load()
            return self._value


class FrameWriter:
    """Positions (V, 3) -> frame GLB: the fast plain writer, or the look-keeping one for glTF/OBJ sources."""

    def __init__(self, fast: Callable[[np.ndarray], bytes], layout: LazyLayout) -> None:
        self.fast, self.layout = fast, layout
        self._look: Callable[[np.ndarray], bytes] | None = None

    @property
    def ready(self) -> bool:
        """Whether a frame can be written without I/O or set-up (the layout and its writer are built)."""
        return self.layout.loaded and (self.layout.get().source == "plain" or self._look is not None)

    def __call__(self, positions: np.ndarray) -> bytes:
        """GLB bytes of one frame."""
        layout = self.layout.get()
        if layout.source == "plain":
            return self.fast(positions)
        if self._look is None:  # a duplicate build by a concurrent request is harmless
            from pdeanim.gltf.compact import LayoutFrames

            self._look = LayoutFrames(layout)
        return self._look(positions)


def source_layout_loader(store: Any, mesh_id: str, clip: Any) -> LazyLayout:
    """A LazyLayout reading the clip's mesh file (the uploaded original) from the store."""

    def load() -> Any:
        from pdeanim.gltf.layout import source_layout

        from ..store.models import Mesh

        with store.sessions() as session:
            mesh = session.get(Mesh, mesh_id)
            key, name = (mesh.blob_key, mesh.filename) if mesh is not None else (None, "")
        data = store.blobs.get(key) if key else None
        return source_layout(data, name, clip.faces, clip.n_vertices)

    return LazyLayout(load)


def check_fps(fps: float, settings: Settings) -> None:
    """422 unless 0 < fps <= PDEANIM_MAX_EXPORT_FPS."""
    if not np.isfinite(fps) or not 0 < fps <= settings.max_export_fps:
        raise ApiError(422, "fps_out_of_range", f"fps must lie in (0, {settings.max_export_fps:g}] "
                       f"(PDEANIM_MAX_EXPORT_FPS), got {fps:g}")


def export_job_hint(clip_id: str, fps: float) -> str:
    """How to ask for an export that is too large for the request: the job to submit and where to get it."""
    return (f'submit an export job: POST /v1/jobs {{"kind": "export", "clip_id": "{clip_id}", '
            f'"fps": {fps:g}}}, then download GET /v1/exports/{{job_id}} when the job has succeeded')
