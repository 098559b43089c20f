"""``pdeanim keys create --tenant NAME``: print a new API key for a tenant (created if new)."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``keys`` sub-command."""
    p = subparsers.add_parser("keys", help="manage API keys")
    sub = p.add_subparsers(dest="keys_command", required=True)
    create = sub.add_parser("create", help="print a new API key for TENANT")
    create.add_argument("--tenant", required=True, help="tenant name (created if it does not exist)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Create the key (migrating the database first) and print it on stdout."""
    from service.settings import Settings
    from service.store.tenants import issue_key

    print(issue_key(Settings(), args.tenant))
    return 0
