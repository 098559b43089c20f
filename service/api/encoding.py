"""Content-Encoding of large, already meshopt-compressed bodies (animation and export GLBs): zstd where the
client accepts it (Chrome, Firefox, httpx with zstandard), gzip otherwise, chosen per request from
Accept-Encoding (RFC 9110 12.5.3), encoded by the route (in the thread pool, not on the event loop as the
gzip middleware would) and kept in the encoded-body LRU."""

from __future__ import annotations

import gzip
from collections.abc import Callable, Hashable

from fastapi import Request, Response

from .cache import BodyCache
from .httpcache import IMMUTABLE, etag_matches, immutable_response

# Measured on a 4.8 MB meshopt animation GLB (2026-11-27): zstd level 3 leaves 0.83 of it in 18 ms; gzip
# level 6 0.87 in 138 ms, level 1 0.88 in 92 ms. Level 3's window (2 MiB) stays within the 8 MiB that HTTP
# decoders must support (RFC 8878 3.1.1.1.2).
ZSTD_LEVEL = 3
GZIP_LEVEL = 1
CODINGS = ("zstd", "gzip")  # preference order of what the server offers


def accepted_coding(accept_encoding: str, offered: tuple[str, ...] = CODINGS) -> str | None:
    """The first of ``offered`` that ``accept_encoding`` admits with q > 0 (named, or through ``*``), or
    None for the body as it is."""
    weights: dict[str, float] = {}
    for part in accept_encoding.lower().split(","):
        name, _, params = part.partition(";")
        name = name.strip()
        if not name:
            continue
        q = 1.0
        for param in params.split(";"):
            key, _, value = param.partition("=")
            if key.strip() == "q":
                try:
                    q = float(value)
                except ValueError:
                    q = 0.0
        weights[name] = q
    for coding in offered:
        if weights.get(coding, weights.get("*", 0.0)) > 0:
            return coding
    return None


def encode(body: bytes, coding: str) -> bytes:
    """``body`` in the content coding ``coding`` (one of CODINGS)."""
    if coding == "zstd":
        import zstandard

        return zstandard.ZstdCompressor(level=ZSTD_LEVEL, write_content_size=True).compress(body)
    if coding == "gzip":
        return gzip.compress(body, GZIP_LEVEL, mtime=0)
    raise ValueError(f"unknown content coding {coding!r}")


def negotiated_response(request: Request, tag: str, body: Callable[[], bytes], media_type: str,
                        cache: BodyCache, key: tuple[Hashable, ...]) -> Response:
    """The immutable response (ETag ``tag``, 304 when matched) of ``body()`` in the best coding the request
    accepts, the encoded bytes kept in ``cache`` under ``key`` + the coding; else the body as it is (never
    re-encoded by the gzip middleware)."""
    vary = {"Vary": "Accept-Encoding"}
    coding = accepted_coding(request.headers.get("accept-encoding", ""))
    if coding is None:
        return immutable_response(request, tag, body, media_type, vary, compress=False)
    if etag_matches(request, f'"{tag}"'):  # the 304 names the ETag the encoded 200 had: the weak one
        return Response(status_code=304, headers={"ETag": f'W/"{tag}"', "Cache-Control": IMMUTABLE, **vary})

    def encoded() -> bytes:
        data = cache.get((*key, coding))
        if data is None:
            data = encode(body(), coding)
            cache.put((*key, coding), data)
        return data

    # passed through by the gzip middleware (Content-Encoding set), and given a weak ETag
    return immutable_response(request, tag, encoded, media_type, {"Content-Encoding": coding, **vary})
