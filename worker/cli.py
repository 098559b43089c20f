"""``pdeanim worker``: run a job worker on the settings in the environment (PDEANIM_*) until SIGTERM."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``worker`` sub-command."""
    p = subparsers.add_parser("worker", help="run a job worker (settings from PDEANIM_* environment "
                                             "variables)")
    p.add_argument("--log-level", default="INFO", help="logging level (default INFO)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Start the worker loop; returns 0 after a clean stop."""
    import logging

    from pdeanim_worker.loop import main

    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    return main()
