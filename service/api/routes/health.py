"""GET /healthz: liveness and readiness (database and blob store reachable)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from ..access import responses
from ..deps import StoreDep
from ..errors import ApiError
from ..schemas import ErrorOut, Health

router = APIRouter(tags=["health"])


@router.get("/healthz", operation_id="healthz", response_model=Health,
            responses={**responses(),
                       503: {"model": ErrorOut, "description": "database or blob store unreachable"}})
def healthz(store: StoreDep) -> JSONResponse:
    """200 when the database (with the jobs table) and the blob store answer, else 503 in the one error shape
    with each failing part's reason in the message."""
    status = store.check()
    failing = {part: reason for part, reason in status.items() if reason != "ok"}
    if failing:
        raise ApiError(503, "unavailable", "; ".join(f"{part}: {reason}" for part, reason in failing.items()))
    return JSONResponse({"status": "ok", **status}, 200)
