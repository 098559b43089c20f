"""Warm start: before an API process accepts its first request, import what the clip routes use and run a
few tiny bundled clips (one per kind of evaluator: rigid, displacement, absolute, spline and PDE tangents,
windows, blend basis, cyclic, bones with a residual and its skinned export) through decoding, evaluation, the
frame GLB and a short animation, so that numba's compiled kernels are loaded (from its on-disk cache, or
compiled) by then. In a cold process the first frame requests otherwise waited for these imports and kernels
(0.5 s and more) on top of loading their clip."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

log = logging.getLogger("pdeanim.api")
WARMUP_DIR = Path(__file__).resolve().parent / "warmup"
WARM_T = (0.0, 0.37, 1.0)


def warmup_clips() -> list[Path]:
    """The bundled tiny clips (package data), sorted by name."""
    return sorted(WARMUP_DIR.glob("*.clip"))


def warm_clip_routes() -> float:
    """Import the evaluation and GLB modules and exercise them on each bundled clip; returns the seconds it
    took. A clip that fails (e.g. after a format change) is logged and skipped: warming never stops
    start-up."""
    started = time.perf_counter()
    import numpy as np

    from pdeanim.clip import load_clip_file
    from pdeanim.gltf.clipexport import clip_animation_glb, estimate_export  # noqa: F401 - animation route
    from pdeanim.gltf.compact import LayoutFrames  # noqa: F401 - frames of glTF/OBJ sources
    from pdeanim.gltf.layout import source_layout  # noqa: F401 - the source's look, read on first frame
    from pdeanim.gltf.write import FrameGlb

    for path in warmup_clips():
        try:
            clip = load_clip_file(path)
            writer = FrameGlb(clip.faces, clip.n_vertices)
            for t in WARM_T:
                writer(np.asarray(clip.evaluate(t)))
            clip_animation_glb(clip, 4.0, max_frames=64)
        except Exception as exc:  # noqa: BLE001 - a stale warm-up file must not keep the API down
            log.warning("warm-up clip %s failed: %r", path.name, exc)
    seconds = time.perf_counter() - started
    log.info("warm start: clip modules and kernels ready in %.2f s", seconds)
    return seconds


def preload_recent_clips(store: Any, cache: Any, count: int) -> list[str]:
    """Decode the ``count`` newest clips (any tenant) into ``cache`` before requests arrive, so that the first
    frame requests of a fresh process do not wait for their clip (0.25-0.3 s for 20k vertices, more for long
    or dense clips); returns the ids loaded. A clip that fails to load is logged and skipped."""
    if count <= 0:
        return []
    from sqlalchemy import select

    from ..store.models import ClipRecord
    from .routes.clips import load_into

    started = time.perf_counter()
    try:
        with store.sessions() as session:
            ids = list(session.scalars(select(ClipRecord.id).order_by(ClipRecord.created_at.desc())
                                       .limit(count)))
    except Exception as exc:  # noqa: BLE001 - the database may be down at start: requests answer 503 then
        log.warning("preloading clips skipped: %r", exc)
        return []
    loaded = []
    for clip_id in ids:
        try:
            load_into(cache, clip_id, store)
            loaded.append(clip_id)
        except Exception as exc:  # noqa: BLE001 - a damaged clip answers its own requests with the error
            log.warning("preloading clip %s failed: %r", clip_id, exc)
    log.info("warm start: %d newest clip(s) decoded in %.2f s", len(loaded), time.perf_counter() - started)
    return loaded
