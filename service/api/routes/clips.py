"""Clips: metadata, the coefficient set (binary or JSON), one frame at t, and the whole animation as GLB."""

from __future__ import annotations

import hashlib
import math
from typing import Literal

import numpy as np
from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from pdeanim.records import jsonable

from ...store.context import Store
from ...store.models import ClipRecord
from ..access import owned, responses
from ..cache import CachedClip
from ..deps import ClipCacheDep, SessionDep, StoreDep, TenantDep
from ..encoding import negotiated_response
from ..errors import ApiError
from ..exports import FrameWriter, check_fps, export_job_hint, source_layout_loader
from ..httpcache import IMMUTABLE, NO_COMPRESSION, etag_matches, immutable_response
from ..invalidation import not_found
from ..schemas import ClipOut
from ..streaming import StreamBody, ranged_response, stream_body, stream_tag, window_body

router = APIRouter(tags=["clips"])
GLB = "model/gltf-binary"
GLB_RESPONSE = {200: {"content": {GLB: {}}, "description": "a binary glTF 2.0 file"}}
SUMMARY_KEYS = ("rms", "max", "rel_rms", "rel_max", "p95", "target")
# New frames of clips up to this many vertices are computed on the event loop (the cost grows with the
# vertices: about 0.35 ms at 20k), larger ones in the thread pool so the process keeps answering meanwhile.
INLINE_FRAME_VERTICES = 50_000


def _load(clip_id: str, store: Store, cache) -> CachedClip:  # noqa: ANN001
    """The clip from the cache, or read and decoded from the database row and blobs (blocking I/O)."""
    def load() -> CachedClip:
        from pdeanim.clip import open_clip
        from pdeanim.gltf.write import FrameGlb

        with store.sessions() as session:
            row = session.get(ClipRecord, clip_id)
        if row is None:
            raise ApiError(404, "not_found", f"clip {clip_id!r} not found")
        # a clip whose decoding would take more than the cache may hold is evaluated a block of curves at a
        # time (the same bytes, in bounded memory, computed per request), never decoded whole
        clip = open_clip(store.blobs.get(row.topology_key), store.blobs.get(row.coefficients_key),
                         cache.max_bytes)
        layout = source_layout_loader(store, row.mesh_id, clip)  # keeps a glTF/OBJ source's look
        return CachedClip(row.tenant_id, row.coefficients_key, row.topology_key, clip,
                          FrameWriter(FrameGlb(clip.faces, clip.n_vertices), layout))

    return cache.get(clip_id, load)


def load_into(cache, clip_id: str, store: Store) -> CachedClip:  # noqa: ANN001 - a ClipCache
    """The clip from ``cache``, loaded into it first if needed (blocking: database and blobs)."""
    return _load(clip_id, store, cache)


def _owned(item: CachedClip, clip_id: str, tenant: str) -> CachedClip:
    if item.tenant_id != tenant:
        raise ApiError(404, "not_found", f"clip {clip_id!r} not found")
    return item


def _cached(clip_id: str, tenant: str, store: Store, cache) -> CachedClip:  # noqa: ANN001
    return _owned(_load(clip_id, store, cache), clip_id, tenant)


def _count(info: dict, report: dict, name: str) -> int | None:
    for source in (info, report):
        for key in (name, f"n_{name}"):
            value = source.get(key)
            if isinstance(value, list):
                return len(value)
            if isinstance(value, int) and not isinstance(value, bool):
                return value
    return None


def clip_out(row: ClipRecord, info: dict) -> ClipOut:
    """Wire form of a clip: counts from the clip's info, errors and sizes from the producer's report."""
    report = row.report or {}
    errors = {k: report[k] for k in SUMMARY_KEYS if k in report and not isinstance(report[k], list | dict)}
    for source in (report.get("errors"), info.get("errors")):
        if isinstance(source, dict):
            errors.update({k: v for k, v in source.items() if not isinstance(v, list | dict)})
    return ClipOut(id=row.id, kind=row.kind, mesh_id=row.mesh_id, poses_id=row.poses_id, job_id=row.job_id,
                   topology_id=row.topology_id, looping=info.get("looping"), sizes=report.get("sizes", {}),
                   errors=errors, info=info, created_at=row.created_at, frames=_count(info, report, "frames"),
                   segments=_count(info, report, "segments"), curves=_count(info, report, "curves"))


@router.get(
    "/v1/clips/{clip_id}", operation_id="getClip", response_model=ClipOut, responses=responses(401, 404, 422)
)
def get_clip(
    clip_id: str, tenant: TenantDep, session: SessionDep, store: StoreDep, cache: ClipCacheDep
) -> ClipOut:
    """Frames, segments, curves, sizes in bytes and the errors achieved."""
    row = owned(session, ClipRecord, clip_id, tenant, "clip")
    info = jsonable(_info(row, store, cache))
    return clip_out(row, info)


def _info(row: ClipRecord, store: Store, cache) -> dict:  # noqa: ANN001 - a ClipCache
    """The clip's metadata: from its decoded clip when this process holds it, else from the parts' headers
    (nothing that grows with segments x vertices is decoded for it)."""
    from pdeanim.clip import clip_info

    item = cache.peek(row.id)
    if item is not None and item.tenant_id == row.tenant_id:
        info = item.clip.info()
        info.setdefault("looping", bool(item.clip.looping))
        return info
    info = clip_info(store.blobs.get(row.topology_key), store.blobs.get(row.coefficients_key))
    info.setdefault("looping", False)
    return info


STREAM_RESPONSES = {
    200: {"content": {"application/octet-stream": {}, "application/json": {}},
          "description": "the coefficients part: pdeanim container, or its JSON form"},
    206: {"content": {"application/octet-stream": {}},
          "description": "the bytes a single Range selects (layout=stream), with Content-Range"},
}


@router.get("/v1/clips/{clip_id}/coefficients", operation_id="getClipCoefficients", response_class=Response,
            responses={**STREAM_RESPONSES, **responses(304, 401, 404, 416, 422)})
def get_coefficients(clip_id: str, request: Request, tenant: TenantDep, session: SessionDep,
                     store: StoreDep,
                     layout: Literal["whole", "stream"] = Query(
                         "whole", description="'whole' (default): the part as stored (format 1.0/1.1); "
                         "'stream': the streamable layout (format 1.2, feature 'stream'): windows of time "
                         "that decode on their own, in time order after the header and index, served with "
                         "byte ranges (Range, 206, 416) and per window at .../coefficients/windows/{index}"),
                     ) -> Response:
    """The compact coefficient set (binary container; ``Accept: application/json`` for the JSON form);
    ``layout=stream`` for the streamable layout (dynamic-PDE clips; 422 ``not_streamable`` otherwise)."""
    row = owned(session, ClipRecord, clip_id, tenant, "clip")
    json_form = "application/json" in request.headers.get("accept", "")
    if layout == "stream" and not json_form and _unchanged(request, row, store, ""):
        return _not_modified(row, store, "", {"Vary": "Accept"})
    stream = _stream(row, store, request) if layout == "stream" else None
    if json_form:  # streamed: the text is never held whole
        from pdeanim.container import iter_json

        tag = stream_tag(row.coefficients_key, stream.window_seconds) if stream else row.coefficients_key
        headers = {"ETag": f'"{tag}-json"', "Cache-Control": IMMUTABLE, "Vary": "Accept"}
        if etag_matches(request, headers["ETag"]):
            return Response(status_code=304, headers=headers)
        body = iter_json(stream.body if stream else store.blobs.get(row.coefficients_key))
        return StreamingResponse(body, media_type="application/json", headers=headers)
    if stream is not None:
        return ranged_response(request, stream_tag(row.coefficients_key, stream.window_seconds), stream.body,
                               {"Vary": "Accept", "X-Pdeanim-Windows": str(len(stream.windows))})
    return immutable_response(request, row.coefficients_key, lambda: store.blobs.get(row.coefficients_key),
                              "application/octet-stream", {"Vary": "Accept"})


def _unchanged(request: Request, row: ClipRecord, store: Store, suffix: str) -> bool:
    """Whether If-None-Match names the streamable part's ETag (plus ``suffix``: a window's)."""
    return etag_matches(request, f'"{stream_tag(row.coefficients_key, store.settings.stream_window_seconds)}'
                                 f'{suffix}"')


def _not_modified(row: ClipRecord, store: Store, suffix: str, headers: dict[str, str]) -> Response:
    """304 for the streamable part (or a window of it), without converting anything."""
    tag = stream_tag(row.coefficients_key, store.settings.stream_window_seconds) + suffix
    return Response(status_code=304, headers={"ETag": f'"{tag}"', "Cache-Control": IMMUTABLE,
                                              "Accept-Ranges": "bytes", **headers, **NO_COMPRESSION})


def _stream(row: ClipRecord, store: Store, request: Request) -> StreamBody:
    """The clip's coefficients in the streamable layout (converted once, kept in the body LRU)."""
    return stream_body(row.id, row.coefficients_key, lambda: store.blobs.get(row.topology_key),
                       lambda: store.blobs.get(row.coefficients_key), request.app.state.frame_cache,
                       store.settings.stream_window_seconds)


@router.get("/v1/clips/{clip_id}/coefficients/windows/{index}", operation_id="getClipCoefficientsWindow",
            response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}},
                             "description": "window ``index`` of the streamable layout: its inner container"},
                       206: STREAM_RESPONSES[206], **responses(304, 401, 404, 416, 422)})
def get_coefficients_window(clip_id: str, index: int, request: Request, tenant: TenantDep,
                            session: SessionDep, store: StoreDep) -> Response:
    """One window of the streamable layout (``GET .../coefficients?layout=stream``) with its start state
    (the ``start_*`` arrays of docs/format.md §3.10), so that it decodes with the part's head alone: for a
    player that seeks (it has the header, index and head already). Own ETag; 404 ``window_not_found`` past
    the last window."""
    row = owned(session, ClipRecord, clip_id, tenant, "clip")
    if _unchanged(request, row, store, f"-w{index}"):  # nothing to build for a client that has it
        return _not_modified(row, store, f"-w{index}", {})
    stream = _stream(row, store, request)
    if not 0 <= index < len(stream.windows):
        raise ApiError(404, "window_not_found", f"clip {clip_id!r} has {len(stream.windows)} windows "
                                               f"(0..{len(stream.windows) - 1}), not {index}")
    tag = f"{stream_tag(row.coefficients_key, stream.window_seconds)}-w{index}"
    body = window_body(row.id, row.coefficients_key, lambda: store.blobs.get(row.topology_key), stream, index,
                       request.app.state.frame_cache)
    return ranged_response(request, tag, body, {"X-Pdeanim-Windows": str(len(stream.windows))})


@router.get("/v1/clips/{clip_id}/topology", operation_id="getClipTopology", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}},
                             "description": "the topology part (pdeanim container)"},
                       **responses(304, 401, 404, 422)})
def get_clip_topology(clip_id: str, request: Request, tenant: TenantDep, session: SessionDep,
                      store: StoreDep) -> Response:
    """The static part this clip's coefficients evaluate on (shared by clips with the same
    ``topology_id``)."""
    row = owned(session, ClipRecord, clip_id, tenant, "clip")
    return immutable_response(request, row.topology_key, lambda: store.blobs.get(row.topology_key),
                              "application/octet-stream")


@router.get("/v1/clips/{clip_id}/frame", operation_id="getClipFrame", response_class=Response,
            responses={**GLB_RESPONSE, **responses(304, 401, 404, 422)})
async def get_frame(clip_id: str, request: Request, tenant: TenantDep,
                    t: float = Query(..., description="normalised time in [0, 1] (any t if looping)"),
                    ) -> Response:
    """One evaluated frame at ``t`` as a GLB."""
    # The hot path of the service (see the README's performance section for the measurements behind it):
    # ``async def`` with async dependencies, so a repeated frame (encoded-frame LRU) or a 304 costs no
    # thread-pool hop; a clip is loaded (database, blobs) in the pool once per process. A new frame of a
    # clip up to INLINE_FRAME_VERTICES is computed right here on the event loop (about 0.35 ms for 20k
    # vertices): the hop to the pool and the threads' contention for the GIL cost more server CPU per
    # request than the loop waiting that long; larger frames go to the pool.
    state = request.app.state
    item = state.clip_cache.peek(clip_id)
    if item is None:
        item = await run_in_threadpool(_load, clip_id, state.store, state.clip_cache)
    await state.deletions.ensure(state.store)  # no I/O unless this process fell behind its checks
    if state.clip_cache.is_gone(clip_id):
        raise not_found(clip_id)
    _owned(item, clip_id, tenant)
    if not math.isfinite(t) or (not item.clip.looping and not 0.0 <= t <= 1.0):
        raise ApiError(422, "t_out_of_range", f"t must lie in [0, 1] for this clip, got {t}")
    etag = '"' + hashlib.sha256(f"{item.coefficients_key}:frame:{t!r}".encode()).hexdigest() + '"'
    headers = {
        "ETag": etag,
        "Cache-Control": IMMUTABLE,
        **NO_COMPRESSION,
    }  # float32 frames: gzip not worth it
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    body = state.frame_cache.get((clip_id, t))
    if body is None:
        if item.frame_glb.ready and item.clip.n_vertices <= INLINE_FRAME_VERTICES:
            body = _frame_body(item, float(t))
        else:  # the first frame loads the source layout (I/O); a large frame would hold up the loop
            body = await run_in_threadpool(_frame_body, item, float(t))
        state.frame_cache.put((clip_id, t), body)
    return Response(body, media_type=GLB, headers=headers)


def _frame_body(item: CachedClip, t: float) -> bytes:
    """The GLB of the clip's frame at ``t``."""
    return item.frame_glb(np.asarray(item.clip.evaluate(t)))


@router.get("/v1/clips/{clip_id}/animation", operation_id="getClipAnimation", response_class=Response,
            responses={**GLB_RESPONSE, **responses(304, 401, 404, 413, 422)})
def get_animation(clip_id: str, request: Request, tenant: TenantDep, store: StoreDep, cache: ClipCacheDep,
                  fps: float = Query(30.0, gt=0,
                                     description="frames per second (at most PDEANIM_MAX_EXPORT_FPS)")
                  ) -> Response:
    """The whole clip sampled at ``fps`` (last frame included; a looping clip wraps seamlessly) as a GLB:
    one morph target per frame and a weights animation, quantised (KHR_mesh_quantization) and compressed
    (EXT_meshopt_compression), keeping a glTF source's materials, textures, UVs, primitives and node names.
    Sent zstd-encoded where Accept-Encoding allows it, else gzip-encoded where that is allowed. Exports
    whose sampled frames exceed PDEANIM_MAX_SYNC_EXPORT_BYTES (raw float32) answer 413
    ``export_too_large``: submit an ``export`` job instead."""
    from pdeanim.gltf.clipexport import estimate_export

    settings = store.settings
    check_fps(fps, settings)
    item = _cached(clip_id, tenant, store, cache)
    request.app.state.deletions.ensure_blocking(store)
    if cache.is_gone(clip_id):
        raise not_found(clip_id)
    estimate = estimate_export(item.clip, fps, settings.max_frames)
    if estimate.raw_frame_bytes > settings.max_sync_export_bytes:
        raise ApiError(413, "export_too_large",
                       f"this export samples {estimate.frames} frames x {estimate.vertices} vertices "
                       f"({estimate.raw_frame_bytes} bytes as raw float32), more than a request builds "
                       f"(PDEANIM_MAX_SYNC_EXPORT_BYTES = {settings.max_sync_export_bytes}); "
                       + export_job_hint(clip_id, fps))
    tag = hashlib.sha256(f"{item.coefficients_key}:animation:meshopt-v3:{fps!r}".encode()).hexdigest()

    def body() -> bytes:  # kept in the encoded-body LRU with the frames (a repeat is a copy-free answer)
        from pdeanim.gltf.clipexport import clip_animation_glb

        cache = request.app.state.frame_cache
        data = cache.get(("animation", clip_id, fps))
        if data is None:
            layout = item.frame_glb.layout.get()
            data = clip_animation_glb(item.clip, fps, layout=layout, max_frames=settings.max_frames)
            cache.put(("animation", clip_id, fps), data)
        return data

    return negotiated_response(request, tag, body, GLB, request.app.state.frame_cache,
                               ("animation", clip_id, fps))


@router.head("/v1/clips/{clip_id}/animation", operation_id="headClipAnimation", response_class=Response,
             responses={**GLB_RESPONSE, **responses(304, 401, 404, 413, 422)})
def head_animation(clip_id: str, request: Request, tenant: TenantDep, store: StoreDep, cache: ClipCacheDep,
                   fps: float = Query(30.0, gt=0,
                                      description="frames per second (at most PDEANIM_MAX_EXPORT_FPS)")
                   ) -> Response:
    """The headers ``GET`` of the animation answers, without its body: ``Content-Length`` is its size in the
    coding the request accepts (the viewer shows it next to the clip's bytes without downloading it)."""
    return get_animation(clip_id, request, tenant, store, cache, fps)
