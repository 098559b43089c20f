"""The streamable layout of a clip's coefficients over HTTP (docs/http.md, docs/format.md §3.10): converted
from the stored part on first request (the same bytes every time, so ETags agree between processes), kept in
the encoded-body LRU whole and per window, served with byte ranges (``Range`` / ``206 Partial Content`` /
``416``, RFC 9110 §14) and one route per window, each with its own ETag."""

from __future__ import annotations

import re
import threading
from collections.abc import Callable
from dataclasses import dataclass

from fastapi import Request, Response

from .cache import BodyCache
from .errors import ApiError
from .httpcache import IMMUTABLE, NO_COMPRESSION, etag_matches

STREAM_TAG = "stream1"
"""Version of the conversion (its window choice and encodings) in every ETag of the streamable layout: a
writer whose bytes differ must change it, so that no cache mixes the two."""
LAYOUTS = ("whole", "stream")
OCTETS = "application/octet-stream"
_RANGE = re.compile(r"^\s*bytes\s*=\s*(\d*)\s*-\s*(\d*)\s*$", re.IGNORECASE)
_converting: dict[str, threading.Lock] = {}
_guard = threading.Lock()


def stream_tag(coefficients_key: str, window_seconds: float) -> str:
    """The ETag (unquoted) of a clip's streamable part: its coefficients, the conversion's version and
    window length (a server with another PDEANIM_STREAM_WINDOW_SECONDS writes other bytes)."""
    return f"{coefficients_key}-{STREAM_TAG}-{window_seconds:g}s"


@dataclass(frozen=True)
class StreamBody:
    """The streamable part of a clip and the byte range of each window in it."""

    body: bytes
    windows: tuple[tuple[int, int], ...]  # (start, end) of every window's inner container
    window_seconds: float


def stream_body(clip_id: str, coefficients_key: str, topology: Callable[[], bytes],
                coefficients: Callable[[], bytes], cache: BodyCache, window_seconds: float) -> StreamBody:
    """The clip's coefficients in the streamable layout with windows of ``window_seconds`` (the setting
    PDEANIM_STREAM_WINDOW_SECONDS): from ``cache`` (key ``("stream", clip_id, ...)``, dropped with the clip),
    else converted from the stored parts once per process at a time. Raises ApiError 422 ``not_streamable``
    for a clip kind without time windows."""
    key = ("stream", clip_id, coefficients_key, STREAM_TAG, window_seconds)
    body = cache.get(key)
    if body is None:
        with _guard:
            lock = _converting.setdefault(key[2], threading.Lock())
        with lock:
            body = cache.get(key)
            if body is None:
                body = _convert(topology(), coefficients(), window_seconds)
                cache.put(key, body)
        with _guard:
            _converting.pop(key[2], None)
    from pdeanim.model.streamlayout import read_index

    _, _, windows = read_index(body)
    return StreamBody(body, tuple((w.start, w.end) for w in windows), window_seconds)


def window_body(clip_id: str, coefficients_key: str, topology: Callable[[], bytes], stream: StreamBody,
                index: int, cache: BodyCache) -> bytes:
    """Window ``index`` of the streamable part with its start state (docs/format.md §3.10): it decodes with
    the part's head alone, for a player that seeks; kept in ``cache`` (dropped with the clip)."""
    key = ("stream", clip_id, coefficients_key, STREAM_TAG, stream.window_seconds, "window", index)
    body = cache.get(key)
    if body is None:
        from pdeanim.container import unpack
        from pdeanim.model.clipformat import decode_topology
        from pdeanim.model.streamlayout import StreamClip

        clip = StreamClip(decode_topology(*unpack(topology())), stream.body)
        body = clip.self_contained(index)
        cache.put(key, body)
    return body


def _convert(topology: bytes, coefficients: bytes, window_seconds: float) -> bytes:
    from pdeanim.container import read_header
    from pdeanim.errors import ParameterError
    from pdeanim.model.streamlayout import stream_coefficients

    kind = read_header(coefficients).get("kind")
    if kind != "dynamic-pde":
        raise ApiError(422, "not_streamable", f"a {kind!r} clip has no streamable layout (only dynamic-pde "
                                              "clips are cut into windows of time)")
    try:
        return stream_coefficients(topology, coefficients, window_seconds)
    except ParameterError as exc:
        raise ApiError(422, "not_streamable", str(exc)) from exc


def parse_range(header: str | None, size: int) -> tuple[int, int] | None:
    """(first, last) byte, inclusive, of a single ``bytes=`` range against a body of ``size`` bytes; None to
    send the whole body (no Range, another unit, several ranges or a malformed one, which RFC 9110 §14.2 lets
    a server ignore). Raises ApiError 416 for a range that selects nothing."""
    if not header:
        return None
    m = _RANGE.match(header)
    if m is None:
        return None
    first, last = m.group(1), m.group(2)
    if not first and not last:
        return None
    if not first:  # the last n bytes
        n = int(last)
        if n == 0 or size == 0:
            raise _unsatisfiable(size)
        return max(0, size - n), size - 1
    a = int(first)
    b = size - 1 if not last else min(int(last), size - 1)
    if last and int(last) < a:
        return None  # invalid (last before first): ignored, the whole body
    if a >= size:
        raise _unsatisfiable(size)
    return a, b


def _unsatisfiable(size: int) -> ApiError:
    return ApiError(416, "range_not_satisfiable", f"the range selects no byte of the {size}-byte body",
                    headers={"Content-Range": f"bytes */{size}", "Accept-Ranges": "bytes"})


def ranged_response(request: Request, tag: str, body: bytes, headers: dict[str, str]) -> Response:
    """The immutable ``body`` (ETag ``tag``) with byte ranges: 304 when If-None-Match names it, 206 with
    Content-Range for a satisfiable single range (unless an If-Range names another validator), 416 for an
    unsatisfiable one, else 200; never content-coded (a range counts bytes of the body as it is)."""
    etag = f'"{tag}"'
    common = {"ETag": etag, "Cache-Control": IMMUTABLE, "Accept-Ranges": "bytes", **headers, **NO_COMPRESSION}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=common)
    if_range = request.headers.get("if-range")
    if if_range is not None and if_range.strip() != etag:
        return Response(body, media_type=OCTETS, headers=common)  # changed (or dated): the whole body
    span = parse_range(request.headers.get("range"), len(body))
    if span is None:
        return Response(body, media_type=OCTETS, headers=common)
    a, b = span
    common["Content-Range"] = f"bytes {a}-{b}/{len(body)}"
    return Response(body[a:b + 1], status_code=206, media_type=OCTETS, headers=common)
