"""The bare reference app of ``service_frames.py``: FastAPI with nothing but one route that evaluates a
cosh/sinh blend of two 15k x 3 float32 arrays at ``t`` and answers a body of ``BARE_BODY_BYTES`` bytes
(the size of the project's frame GLB), so it costs what the web stack plus a small evaluation costs.

    BARE_BODY_BYTES=718000 .venv/bin/uvicorn benchmarks.bare_frames_app:app --workers 2 --port 8100
"""

from __future__ import annotations

import os

import numpy as np
from fastapi import FastAPI, Response

N = 15_000
SIZE = int(os.environ.get("BARE_BODY_BYTES", str(N * 3 * 4)))
_rng = np.random.default_rng(0)
A = _rng.standard_normal((N, 3)).astype(np.float32)
B = _rng.standard_normal((N, 3)).astype(np.float32)

app = FastAPI()


@app.get("/frame")
async def frame(t: float) -> Response:
    """cosh(t) A + sinh(t) B, its bytes repeated to the body size."""
    blend = (np.cosh(t) * A + np.sinh(t) * B).astype(np.float32).tobytes()
    body = (blend * (SIZE // len(blend) + 1))[:SIZE]
    return Response(body, media_type="application/octet-stream")
