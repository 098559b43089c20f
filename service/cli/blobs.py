"""``pdeanim blobs sweep``: remove the blobs that no row names (what each worker does every
``PDEANIM_BLOB_SWEEP_SECONDS``), with the same ``PDEANIM_*`` settings as the server."""

from __future__ import annotations

import argparse
import json


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``blobs`` sub-command."""
    p = subparsers.add_parser("blobs", help="blob store maintenance")
    sub = p.add_subparsers(dest="blobs_command", required=True)
    sweep = sub.add_parser("sweep", help="remove the blobs that no row names, stored more than the grace ago")
    sweep.add_argument("--grace", type=float, default=None, metavar="SECONDS",
                       help="keep unreferenced blobs stored less than this long ago (default: "
                            "PDEANIM_BLOB_SWEEP_GRACE_SECONDS, 3600)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Sweep once and print what was removed as JSON."""
    from pdeanim_service.settings import Settings
    from pdeanim_service.store.blobrefs import sweep
    from pdeanim_service.store.context import Store

    settings = Settings()
    if args.grace is not None and args.grace < 0:
        print("pdeanim blobs sweep: --grace must be >= 0")
        return 2
    store = Store.open(settings)
    try:
        grace = settings.blob_sweep_grace_seconds if args.grace is None else args.grace
        print(json.dumps({"grace_seconds": grace, **sweep(store, grace).summary()}))
    finally:
        store.close()
    return 0
