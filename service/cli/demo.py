"""``pdeanim demo [MESH]``: the README's end-to-end example through the real service and worker."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``demo`` sub-command."""
    p = subparsers.add_parser("demo", help="start service + worker, simulate and fit a mesh, download GLBs")
    p.add_argument("mesh", nargs="?", type=Path, help="mesh file (default: the sample spot.obj)")
    p.add_argument("--out", type=Path, default=Path("pdeanim-demo"), help="output folder (default "
                                                                          "pdeanim-demo)")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="service data directory (default: a temporary one, removed afterwards)")
    p.add_argument("--keep", action="store_true", help="keep the temporary data directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo; returns 0 on success."""
    from pdeanim_service.demo import run_demo

    return run_demo(args.mesh, args.out, args.data_dir, args.keep)
