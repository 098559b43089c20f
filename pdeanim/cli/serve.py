"""``pdeanim serve [--host H] [--port P]``: migrate the database (embedded default) and run the API."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``serve`` sub-command."""
    p = subparsers.add_parser("serve", help="run the HTTP API (settings from PDEANIM_* environment variables)")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument("--workers", type=int, default=1, help="uvicorn worker processes (default 1)")
    p.add_argument("--no-migrate", action="store_true",
                   help="do not run migrations first (scale-out: a `serve --migrate-only` step runs them)")
    p.add_argument("--migrate-only", action="store_true", help="run the database migrations and exit")
    p.add_argument("--log-level", default="warning")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Migrate (unless --no-migrate), then serve until interrupted."""
    import uvicorn

    from service.settings import Settings
    from service.store.db import migrate

    settings = Settings()
    if not args.no_migrate:
        migrate(settings.resolved_database_url())
    if args.migrate_only:
        print("pdeanim serve: database is at the newest schema")
        return 0
    uvicorn.run("service.api.app:app_from_environment", factory=True, host=args.host, port=args.port,
                workers=args.workers, log_level=args.log_level, access_log=False)
    return 0
