"""One JSON error shape, ``{"error": {"code", "message"}}``, for every 4xx and 5xx the API returns."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from pdeanim.errors import InputError

log = logging.getLogger("pdeanim.api")

STATUS_CODES = {400: "bad_request", 401: "unauthorized", 403: "forbidden", 404: "not_found",
                405: "method_not_allowed", 406: "not_acceptable", 408: "request_timeout", 409: "conflict",
                413: "payload_too_large", 415: "unsupported_media_type", 422: "validation_error",
                429: "too_many_requests", 501: "not_implemented", 503: "unavailable"}


class ApiError(StarletteHTTPException):
    """An HTTP error with a stable machine-readable ``code``."""

    def __init__(self, status: int, code: str, message: str, headers: dict[str, str] | None = None):
        super().__init__(status, message, headers)
        self.code = code


def error_body(code: str, message: str) -> dict:
    """The error document."""
    return {"error": {"code": code, "message": message}}


def _leaf_routes(routes: list) -> list:
    """Routes with included routers expanded (FastAPI wraps each include; this app uses no prefixes)."""
    out = []
    for route in routes:
        inner = getattr(route, "original_router", None)
        out += _leaf_routes(inner.routes) if inner is not None else [route]
    return out


def allowed_methods(request: Request) -> list[str]:
    """Every method some route answers on this path (Starlette's 405 names only the first route's)."""
    from starlette.routing import Match

    methods: set[str] = set()
    for route in _leaf_routes(request.app.router.routes):
        match, _ = route.matches(request.scope)
        if match != Match.NONE and getattr(route, "methods", None):
            methods |= set(route.methods)
    return sorted(methods)


def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    code = getattr(exc, "code", None) or STATUS_CODES.get(exc.status_code, f"http_{exc.status_code}")
    message = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
    headers = dict(getattr(exc, "headers", None) or {})
    if exc.status_code == 405:
        headers["Allow"] = ", ".join(allowed_methods(request)) or headers.get("Allow", "")
    return JSONResponse(error_body(code, message), exc.status_code, headers=headers or None)


def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
    parts, errors = [], exc.errors()
    broken = [e for e in errors if e.get("type") == "json_invalid"]
    if broken:  # not JSON at all: a malformed request (400), not a well-formed one with invalid values (422)
        where = tuple(broken[0].get("loc", ()))[1:2]
        at = f" at character {where[0]}" if where else ""
        return JSONResponse(error_body("bad_request", f"malformed JSON body{at}: "
                                       f"{broken[0].get('ctx', {}).get('error', 'JSON decode error')}"), 400)
    for err in errors[:5]:
        loc = ".".join(str(p) for p in err.get("loc", ()))
        parts.append(f"{loc}: {err.get('msg', 'invalid')}")
    # fields of a job body of a known kind (body.<kind>.…) keep the code they had before bodies were typed;
    # a body that is not JSON, not an object or of an unknown kind stays a validation_error
    options = errors and all(tuple(e.get("loc", ()))[:1] == ("body",) and len(e["loc"]) >= 3 for e in errors)
    code = "invalid_parameter" if options else "validation_error"
    return JSONResponse(error_body(code, "; ".join(parts) or "invalid request"), 422)


def _input(_: Request, exc: InputError) -> JSONResponse:
    return JSONResponse(error_body(exc.code, str(exc)), int(getattr(exc, "status", 422)))


RETRY_AFTER_SECONDS = 5


def _unavailable(_: Request, exc: Exception) -> JSONResponse:
    """The database cannot be reached or stayed locked: 503 with Retry-After, not a 500 (nothing is wrong with
    the request; the same request later may succeed)."""
    log.warning(
        "database unavailable: %s", str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__
    )
    return JSONResponse(
        error_body("unavailable", "the database is unavailable; retry later"),
        503,
        headers={"Retry-After": str(RETRY_AFTER_SECONDS)},
    )


def _out_of_memory(_: Request, exc: Exception) -> JSONResponse:
    """An allocation failed while answering: 503 with Retry-After, naming the allocation and the limit (the
    same request may fit once concurrent ones are done), not a 500."""
    from pdeanim.outofmemory import out_of_memory

    message = str(out_of_memory(exc, "retry later, or ask for less at once (a lower fps, fewer frames)"))
    log.warning("%s", message)
    return JSONResponse(error_body("out_of_memory", message), 503,
                        headers={"Retry-After": str(RETRY_AFTER_SECONDS)})


def _unexpected(_: Request, exc: Exception) -> JSONResponse:
    log.exception("unhandled error", exc_info=exc)
    return JSONResponse(error_body("internal", f"internal error ({type(exc).__name__})"), 500)


def install_error_handlers(app: FastAPI) -> None:
    """Map HTTP errors, validation errors, library InputErrors and anything unexpected to the error shape."""
    app.add_exception_handler(StarletteHTTPException, _http)
    app.add_exception_handler(RequestValidationError, _validation)
    app.add_exception_handler(InputError, _input)
    from sqlalchemy.exc import InterfaceError, OperationalError

    app.add_exception_handler(OperationalError, _unavailable)
    app.add_exception_handler(InterfaceError, _unavailable)
    app.add_exception_handler(MemoryError, _out_of_memory)
    app.add_exception_handler(Exception, _unexpected)
