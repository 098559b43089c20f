"""Fair, bounded uploads: each API process receives and validates at most ``PDEANIM_MAX_CONCURRENT_UPLOADS``
uploads at once and at most ``PDEANIM_MAX_TENANT_UPLOADS`` of one tenant (more: 429 with Retry-After, before
the body is read), and a body must keep arriving at ``PDEANIM_UPLOAD_MIN_BYTES_PER_SECOND`` on average after
``PDEANIM_UPLOAD_BODY_GRACE_SECONDS`` (else 408). So a tenant that sends its bodies a byte at a time holds
only its own slots, and only for a bounded time."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from .errors import ApiError

RETRY_AFTER_SECONDS = 2
CLOSE = {"Connection": "close"}  # the unread rest of the body must not be taken for the next request


class UploadSlots:
    """The uploads this process is receiving and validating, bounded per tenant and in all."""

    def __init__(self, total: int, per_tenant: int) -> None:
        self.total, self.per_tenant = total, per_tenant
        self.active = 0
        self.by_tenant: dict[str, int] = {}

    def _refuse(self, message: str) -> ApiError:
        return ApiError(429, "too_many_uploads", f"{message}; retry in a few seconds",
                        headers={"Retry-After": str(RETRY_AFTER_SECONDS), **CLOSE})

    @contextmanager
    def hold(self, tenant: str) -> Iterator[None]:
        """Take a slot of ``tenant`` for the block, or raise 429 with Retry-After when its slots or all are
        taken (the event loop runs one request at a time here: no lock needed)."""
        mine = self.by_tenant.get(tenant, 0)
        if mine >= self.per_tenant:
            raise self._refuse(f"this tenant already has {mine} uploads in progress in this API process, its "
                               "limit (setting PDEANIM_MAX_TENANT_UPLOADS)")
        if self.active >= self.total:
            raise self._refuse(f"this API process is already receiving or validating {self.active} uploads, "
                               "its limit (setting PDEANIM_MAX_CONCURRENT_UPLOADS)")
        self.active += 1
        self.by_tenant[tenant] = mine + 1
        try:
            yield
        finally:
            self.active -= 1
            self.by_tenant[tenant] -= 1
            if not self.by_tenant[tenant]:
                del self.by_tenant[tenant]


@dataclass(frozen=True)
class BodyPace:
    """The slowest an upload body may arrive: ``min_rate`` bytes per second on average after ``grace``
    seconds (0 = no minimum)."""

    min_rate: float
    grace: float

    def seconds_left(self, started: float, received: int) -> float | None:
        """How long the next chunk may take to arrive; None when there is no minimum."""
        if not self.min_rate:
            return None
        return started + self.grace + received / self.min_rate - time.monotonic()

    def too_slow(self, started: float, received: int) -> ApiError:
        """The 408 of a body that fell behind."""
        return ApiError(408, "request_timeout",
                        f"the upload body arrived too slowly: {received} bytes in "
                        f"{time.monotonic() - started:.1f} s; after the first {self.grace:g} s an upload "
                        f"must send at least {self.min_rate:g} bytes per second on average (settings "
                        "PDEANIM_UPLOAD_MIN_BYTES_PER_SECOND, PDEANIM_UPLOAD_BODY_GRACE_SECONDS)",
                        headers=CLOSE)
