"""One cheap ASGI layer around every request: header and JSON body size limits (431/413 before any parsing),
a 500 in the one error shape that keeps the keep-alive connection open, and one access-log line per request
(method, path, status, milliseconds, tenant)."""

from __future__ import annotations

import json
import logging
import time
from typing import Any

from .errors import ApiError, error_body

access_log = logging.getLogger("pdeanim.access")
log = logging.getLogger("pdeanim.api")

Scope = dict[str, Any]


async def _send_error(send, status: int, code: str, message: str) -> None:  # noqa: ANN001
    body = json.dumps(error_body(code, message)).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class RequestGuard:
    """Pure ASGI middleware (no per-request task or body copy): limits, last-resort errors, access log."""

    def __init__(self, app, max_header_bytes: int, max_json_bytes: int,  # noqa: ANN001
                 log_access: bool = True):
        self.app, self.max_header_bytes, self.max_json_bytes = app, max_header_bytes, max_json_bytes
        self.log_access = log_access

    async def __call__(self, scope: Scope, receive, send) -> None:  # noqa: ANN001
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started, status = time.perf_counter(), [0]

        async def tracked_send(message: dict) -> None:
            if message["type"] == "http.response.start":
                status[0] = message["status"]
            await send(message)

        try:
            refusal = self._refusal(scope)
            if refusal is not None:
                await _send_error(tracked_send, *refusal)
            else:
                await self.app(scope, self._counted(scope, receive), tracked_send)
        except Exception as exc:  # noqa: BLE001 - answered here so the server keeps the connection open
            log.exception("unhandled error on %s %s", scope["method"], scope["path"], exc_info=exc)
            if not status[0]:
                await _send_error(tracked_send, 500, "internal", f"internal error ({type(exc).__name__})")
        finally:
            if self.log_access and access_log.isEnabledFor(logging.INFO):
                tenant = scope.get("state", {}).get("tenant", "-")
                access_log.info("%s %s %d %.1fms tenant=%s", scope["method"], scope["path"], status[0],
                                (time.perf_counter() - started) * 1000.0, tenant)

    def _json_message(self) -> str:
        return (f"request body is larger than the limit of {self.max_json_bytes} bytes "
                "(setting PDEANIM_MAX_JSON_BYTES; upload files as multipart/form-data)")

    def _refusal(self, scope: Scope) -> tuple[int, str, str] | None:
        """(status, code, message) when the headers alone show the request is over a limit."""
        headers = scope["headers"]
        size = sum(len(k) + len(v) + 4 for k, v in headers) + len(scope.get("raw_path") or b"")
        if size > self.max_header_bytes:
            return (431, "request_header_fields_too_large",
                    f"request headers are {size} bytes, over the limit of {self.max_header_bytes} "
                    "(setting PDEANIM_MAX_HEADER_BYTES)")
        if self._is_multipart(headers):
            return None  # upload routes stream the body to disk with their own limit
        for k, v in headers:
            if k == b"content-length" and v.isdigit() and int(v) > self.max_json_bytes:
                return 413, "payload_too_large", self._json_message()
        return None

    @staticmethod
    def _is_multipart(headers: list[tuple[bytes, bytes]]) -> bool:
        return any(k == b"content-type" and v[:19].lower() == b"multipart/form-data" for k, v in headers)

    def _counted(self, scope: Scope, receive):  # noqa: ANN001, ANN205
        """``receive`` that raises a 413 ApiError once a non-multipart body passes the JSON limit (an HTTP
        error, so the framework's body reader passes it on to the error handlers instead of calling it a
        400)."""
        if self._is_multipart(scope["headers"]) or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            return receive
        seen = [0]

        async def counted() -> dict:
            message = await receive()
            if message["type"] == "http.request":
                seen[0] += len(message.get("body", b""))
                if seen[0] > self.max_json_bytes:
                    raise ApiError(413, "payload_too_large", self._json_message())
            return message

        return counted
