"""Cursor pagination of a tenant's rows, newest first: ``?limit=&cursor=`` in, ``next_cursor`` out.

The cursor is opaque to clients (URL-safe base64 of the last row's ``created_at`` and ``id``); the next page
is the rows strictly after it in (created_at desc, id desc) order, so rows added meanwhile never shift it.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel, Field
from sqlalchemy import Select, and_, or_
from sqlalchemy.orm import Session

from .errors import ApiError
from .schemas import ClipOut, JobOut, MeshOut, PosesOut

T = TypeVar("T")
DEFAULT_LIMIT, MAX_LIMIT = 50, 200
CURSOR_PATTERN = r"^[A-Za-z0-9_-]{1,400}$"


def encode_cursor(created_at: float, row_id: str) -> str:
    """The cursor naming the position just after a row."""
    raw = json.dumps([created_at, row_id], separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, str]:
    """(created_at, id) of a cursor; 422 ``invalid_cursor`` for anything this service did not make."""
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4))
        created_at, row_id = json.loads(raw)
        number = isinstance(created_at, int | float) and not isinstance(created_at, bool)
        if number and math.isfinite(created_at) and isinstance(row_id, str):
            return float(created_at), row_id
    except (binascii.Error, ValueError, TypeError, UnicodeDecodeError):
        pass
    raise ApiError(422, "invalid_cursor", "cursor is not one this service returned as next_cursor")


def page(session: Session, query: Select, model: Any, limit: int, cursor: str | None,
         out: Callable[[Any], T]) -> tuple[list[T], str | None]:
    """One page of ``query`` (rows of ``model``) after ``cursor``, and the next page's cursor (or None)."""
    if cursor:
        created_at, row_id = decode_cursor(cursor)
        query = query.where(or_(model.created_at < created_at,
                                and_(model.created_at == created_at, model.id < row_id)))
    rows = session.scalars(query.order_by(model.created_at.desc(), model.id.desc()).limit(limit + 1)).all()
    more = len(rows) > limit
    rows = rows[:limit]
    next_cursor = encode_cursor(rows[-1].created_at, rows[-1].id) if more else None
    return [out(row) for row in rows], next_cursor


NEXT = Field(None, description="pass as ?cursor= for the next page; null on the last page")


class MeshPage(BaseModel):
    """A page of meshes, newest first."""

    items: list[MeshOut]
    next_cursor: str | None = NEXT


class PosesPage(BaseModel):
    """A page of poses, newest first."""

    items: list[PosesOut]
    next_cursor: str | None = NEXT


class ClipPage(BaseModel):
    """A page of clips, newest first (``info`` is empty here: GET /v1/clips/{id} for the clip's own info)."""

    items: list[ClipOut]
    next_cursor: str | None = NEXT


class JobPage(BaseModel):
    """A page of jobs, newest first."""

    items: list[JobOut]
    next_cursor: str | None = NEXT


class DeletedOut(BaseModel):
    """What a DELETE removed (blobs still used by other rows are kept)."""

    meshes: int
    poses: int
    clips: int
    jobs: int
    cancelled_jobs: int = Field(description="queued or running jobs cancelled before deletion")
    blobs_removed: int
