"""Tenant-scoped row access: another tenant's ids look exactly like missing ones (404)."""

from __future__ import annotations

from typing import TypeVar

from sqlalchemy.orm import Session

from .errors import ApiError
from .schemas import ErrorOut

T = TypeVar("T")


def owned(session: Session, model: type[T], row_id: str, tenant_id: str, what: str) -> T:
    """The row ``row_id`` of ``model`` if it belongs to ``tenant_id``; else 404 naming ``what``."""
    row = session.get(model, row_id)
    if row is None or row.tenant_id != tenant_id:
        raise ApiError(404, "not_found", f"{what} {row_id!r} not found")
    return row


DESCRIPTIONS = {304: "not modified (If-None-Match matched the ETag)", 400: "malformed request",
                401: "missing or invalid API key", 404: "not found (or another tenant's)",
                408: "the upload body arrived slower than PDEANIM_UPLOAD_MIN_BYTES_PER_SECOND",
                409: "conflict with the resource's state (e.g. an export job still running, a finished job)",
                413: "over a configured limit", 415: "wrong content type",
                416: "the Range selects no byte of the body (Content-Range: bytes */size)",
                422: "invalid input or parameters",
                429: "too many uploads of this tenant or in all at once (Retry-After)",
                501: "stage not available in this build",
                503: "a dependency (database, blobs) is unavailable",
                431: "request headers over PDEANIM_MAX_HEADER_BYTES"}
# the request guard may answer 413/431 on any route (headers; body over the JSON limit); every /v1 route reads
# the database (the API key at least), so each may answer 503 while the database is unreachable
ANY_ROUTE = (413, 431, 503)


def responses(*statuses: int) -> dict[int | str, dict]:
    """OpenAPI ``responses`` for the error statuses a route may answer (plus those every route may answer),
    all with the one error shape."""
    return {s: ({"description": DESCRIPTIONS[s]} if s == 304 else
                {"model": ErrorOut, "description": DESCRIPTIONS[s]}) for s in sorted({*statuses, *ANY_ROUTE})}


def created(status: int, what: str, links: dict[str, tuple[str, str]]) -> dict[int | str, dict]:
    """OpenAPI for a 201/202 answer: its ``Location`` header, and links from the new id to the operations
    that take it (``links``: name -> (operationId, path parameter)), for clients and fuzzers to follow."""
    return {status: {"description": f"the new {what}; Location is its path",
                     "headers": {"Location": {"description": f"path of the new {what}", "required": True,
                                              "schema": {"type": "string"}}},
                     "links": {name: {"operationId": op, "parameters": {param: "$response.body#/id"}}
                               for name, (op, param) in links.items()}}}
