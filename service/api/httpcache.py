"""ETag and long-lived cache headers for immutable resources (clips never change), with 304 handling."""

from __future__ import annotations

from collections.abc import Callable

from fastapi import Request, Response

# A route marks a body not worth compressing (raw float32 frames: gzip saves ~16% at ~10x the CPU time of
# building the frame) with this header; the gzip middleware passes marked bodies through and the marker is
# removed on the way out (middleware.WeakEtagWhenEncoded), so clients never see it.
NO_COMPRESSION = {"Content-Encoding": "identity"}
# private: every such response is tenant data behind an API key, which no shared cache or CDN may keep
IMMUTABLE = "private, max-age=31536000, immutable"


def etag_matches(request: Request, etag: str) -> bool:
    """Whether the request's If-None-Match names ``etag`` (quoted) or is ``*``."""
    header = request.headers.get("if-none-match")
    if not header:
        return False
    tags = [t.strip().removeprefix("W/") for t in header.split(",")]
    return "*" in tags or etag in tags


def immutable_response(request: Request, tag: str, body: Callable[[], bytes], media_type: str,
                       headers: dict[str, str] | None = None, cache_control: str = IMMUTABLE,
                       compress: bool = True) -> Response:
    """304 if the client has ``tag`` already, else the body with ETag and (by default) immutable caching;
    ``compress=False`` sends it as it is even to clients that accept gzip (see NO_COMPRESSION)."""
    etag = f'"{tag}"'
    common = {"ETag": etag, "Cache-Control": cache_control, **(headers or {})}
    if not compress:
        common.update(NO_COMPRESSION)
    if etag_matches(request, etag):
        return Response(status_code=304, headers=common)
    return Response(body(), media_type=media_type, headers=common)
