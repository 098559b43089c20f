"""GET /healthz: liveness and readiness (database and blob store reachable)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from ..access import responses
from ..deps import StoreDep
from ..schemas import Health

router = APIRouter(tags=["health"])


@router.get("/healthz", operation_id="healthz", response_model=Health,
            responses={**responses(),
                       503: {"model": Health, "description": "database or blob store unreachable"}})
def healthz(store: StoreDep) -> JSONResponse:
    """200 when the database (with the jobs table) and the blob store answer, else 503 with the reasons."""
    status = store.check()
    ok = all(v == "ok" for v in status.values())
    return JSONResponse({"status": "ok" if ok else "degraded", **status}, 200 if ok else 503)
