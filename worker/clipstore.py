"""A fitted clip's parts into the blob store, and the clip row's fields (kind, topology id, blob keys, report)
that a job's result hands to the queue: shared by the stages and the windowed fit's join task."""

from __future__ import annotations

from pdeanim.clipparts import ClipParts
from pdeanim.container import unpack
from pdeanim.records import jsonable
from pdeanim_service.store.blobs import BlobStore


def store_clip(parts: ClipParts, blobs: BlobStore, n_frames: int, n_vertices: int) -> dict:
    """Store both parts of ``parts``; the clip's fields with its report (sizes added where missing)."""
    header, _ = unpack(parts.coefficients)
    report = jsonable(parts.report)
    report.setdefault("sizes", jsonable(parts.sizes(n_frames, n_vertices)))
    return {"kind": str(header.get("kind")), "topology_id": parts.topology_id,
            "topology_key": blobs.put(parts.topology), "coefficients_key": blobs.put(parts.coefficients),
            "report": report}
