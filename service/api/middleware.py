"""HTTP for browsers: CORS for configured origins and gzip for compressible bodies (ETags made weak when
the body is encoded, as nginx does, so If-None-Match keeps answering 304 on either representation)."""

from __future__ import annotations

from fastapi import FastAPI
from starlette.datastructures import MutableHeaders
from starlette.middleware.cors import CORSMiddleware
from starlette.middleware.gzip import DEFAULT_EXCLUDED_CONTENT_TYPES, GZipMiddleware
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..settings import Settings
from .errors import error_body

GZIP_MINIMUM_BYTES = 1024  # below about a kilobyte the gzip header and the CPU cost outweigh the saving
GZIP_LEVEL = 6  # zlib's default: most of level 9's ratio on float data at a fraction of its time
CORS_METHODS = ["GET", "HEAD", "POST", "DELETE", "OPTIONS"]
CORS_REQUEST_HEADERS = ["Authorization", "Content-Type", "Accept", "If-None-Match", "Range", "If-Range"]
CORS_EXPOSED_HEADERS = ["ETag", "Content-Length", "Content-Encoding", "Location", "Content-Range",
                        "Accept-Ranges", "X-Pdeanim-Windows"]  # the last three: the streamable layout


class JsonErrorCORSMiddleware(CORSMiddleware):
    """Starlette's CORS middleware, with a refused preflight answered in the API's one error shape."""

    def preflight_response(self, request_headers) -> Response:  # noqa: ANN001
        response = super().preflight_response(request_headers)
        if response.status_code < 400:
            return response
        reason = response.body.decode(errors="replace") or "CORS preflight refused"
        headers = {k: v for k, v in response.headers.items()
                   if k.lower() not in ("content-length", "content-type")}
        return JSONResponse(error_body("cors_refused", f"{reason} (allowed origins: PDEANIM_CORS_ORIGINS)"),
                            response.status_code, headers=headers)


class WeakEtagWhenEncoded:
    """Mark a strong ETag weak (``W/"…"``) on responses sent with a Content-Encoding (RFC 9110 8.8.1), and
    drop the ``Content-Encoding: identity`` marker of bodies sent as they are."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_weak(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(raw=message.setdefault("headers", []))
                if headers.get("content-encoding", "").lower() == "identity":
                    del headers["content-encoding"]
                etag = headers.get("etag")
                if etag and "content-encoding" in headers and not etag.startswith("W/"):
                    headers["ETag"] = "W/" + etag
            await send(message)

        await self.app(scope, receive, send_weak)


class HeadAsGet:
    """Answer ``HEAD`` on every ``GET`` route (RFC 9110 9.3.2): the request runs as a ``GET`` (same status and
    headers, Content-Length and ETag included) and the body is dropped on the way out."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return

        async def send_headers_only(message: Message) -> None:
            if message["type"] == "http.response.body":
                if message.get("more_body", False):
                    return
                message = {"type": "http.response.body", "body": b"", "more_body": False}
            await send(message)

        await self.app({**scope, "method": "GET"}, receive, send_headers_only)


def install_http_middleware(app: FastAPI, settings: Settings) -> None:
    """Gzip (innermost), the weak-ETag rewrite, then CORS when origins are configured, and HEAD as GET
    (outermost, so a HEAD's headers are those of the GET)."""
    app.add_middleware(GZipMiddleware, minimum_size=GZIP_MINIMUM_BYTES, compresslevel=GZIP_LEVEL,
                       exclude_content_types=DEFAULT_EXCLUDED_CONTENT_TYPES)
    app.add_middleware(WeakEtagWhenEncoded)
    origins = settings.cors_origin_list()
    if origins:
        app.add_middleware(JsonErrorCORSMiddleware, allow_origins=origins, allow_methods=CORS_METHODS,
                           allow_headers=CORS_REQUEST_HEADERS, expose_headers=CORS_EXPOSED_HEADERS,
                           allow_credentials=False, max_age=600)
    app.add_middleware(HeadAsGet)
