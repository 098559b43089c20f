"""The installed ``pdeanim`` console script: the library's commands (:mod:`pdeanim.cli`) plus the
service-side ones (``serve``, ``keys``, ``demo`` here and ``worker`` from :mod:`pdeanim_worker.cli`), so the
domain library never imports the service or the worker. The service commands need the ``service`` extra
(``pip install 'pdeanim[service]'``); without it they say so (exit code 2) instead of failing with a
traceback."""

from __future__ import annotations

import sys

from pdeanim.cli import main as library_main

EXTRA = "service"
EXTRA_MODULES = frozenset({"fastapi", "starlette", "uvicorn", "sqlalchemy", "alembic", "psycopg", "boto3",
                           "botocore", "pydantic", "pydantic_settings", "httpx", "multipart",
                           "python_multipart"})
"""Top-level modules of the service extra's distributions: missing one means the extra is not installed."""


def service_commands() -> tuple:
    """The service-side sub-command modules (plain imports; they import the service's packages lazily)."""
    from pdeanim_worker import cli as worker_cli

    from . import blobs, demo, keys, serve

    return serve, worker_cli, keys, blobs, demo


def main(argv: list[str] | None = None) -> int:
    """Run one ``pdeanim`` sub-command, library or service side; returns the exit code."""
    args = sys.argv[1:] if argv is None else argv
    try:
        return library_main(args, service_commands())
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] not in EXTRA_MODULES:
            raise
        command = next((a for a in args if not a.startswith("-")), "")
        print(f"pdeanim {command}: needs the '{EXTRA}' extra (module {exc.name} is not installed): "
              f"pip install 'pdeanim[{EXTRA}]'", file=sys.stderr)
        return 2
