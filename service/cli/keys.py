"""``pdeanim keys create|list|revoke``: make API keys for a tenant, list them, revoke one by id or prefix."""

from __future__ import annotations

import argparse
import json
import sys
import time

MIN_PREFIX = 6  # a shorter prefix matches too many keys to name one


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``keys`` sub-command."""
    p = subparsers.add_parser("keys", help="manage API keys")
    sub = p.add_subparsers(dest="keys_command", required=True)
    create = sub.add_parser("create", help="print a new API key for TENANT")
    create.add_argument("--tenant", required=True, help="tenant name (created if it does not exist)")
    listing = sub.add_parser("list", help="list API keys (id, prefix, tenant, created, revoked), never keys")
    listing.add_argument("--tenant", help="only this tenant's keys")
    listing.add_argument("--json", action="store_true", help="one JSON document instead of a table")
    revoke = sub.add_parser("revoke", help="revoke a key: its requests get 401 from then on")
    revoke.add_argument("key", metavar="KEY_ID_OR_PREFIX",
                        help=f"the key's id (key_...), its listed prefix (>= {MIN_PREFIX} characters), "
                             "or the key itself")
    p.set_defaults(func=run)


def _when(ts: float | None) -> str:
    return "-" if ts is None else time.strftime("%Y-%m-%d %H:%M:%SZ", time.gmtime(ts))


def _list(session, args: argparse.Namespace) -> int:  # noqa: ANN001
    from sqlalchemy import select

    from pdeanim_service.store.models import ApiKey, Tenant

    query = (select(ApiKey, Tenant.name).join(Tenant, Tenant.id == ApiKey.tenant_id)
             .order_by(ApiKey.created_at))
    if args.tenant:
        query = query.where(Tenant.name == args.tenant)
    rows = [{"id": k.id, "prefix": k.prefix, "tenant": name, "created_at": k.created_at,
             "revoked_at": k.revoked_at} for k, name in session.execute(query).all()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'ID':<36}  {'PREFIX':<10}  {'TENANT':<20}  {'CREATED':<20}  REVOKED")
    for r in rows:
        print(f"{r['id']:<36}  {r['prefix']:<10}  {r['tenant'][:20]:<20}  {_when(r['created_at']):<20}  "
              f"{_when(r['revoked_at'])}")
    return 0


def _revoke(session, args: argparse.Namespace) -> int:  # noqa: ANN001
    from sqlalchemy import or_, select

    from pdeanim_service.store.models import ApiKey
    from pdeanim_service.store.tenants import hash_key

    needle = args.key.strip()
    if len(needle) < MIN_PREFIX:
        print(f"error: give the key id or at least {MIN_PREFIX} characters of its prefix", file=sys.stderr)
        return 2
    match = or_(ApiKey.id == needle, ApiKey.key_hash == hash_key(needle),
                ApiKey.prefix.startswith(needle, autoescape=True))
    found = session.scalars(select(ApiKey).where(match)).all()
    if not found:
        print(f"error: no API key matches {needle!r} (see `pdeanim keys list`)", file=sys.stderr)
        return 2
    if len(found) > 1:
        ids = ", ".join(k.id for k in found)
        print(f"error: {needle!r} matches {len(found)} keys ({ids}); give the key id", file=sys.stderr)
        return 2
    key = found[0]
    if key.revoked_at is not None:
        print(f"{key.id} ({key.prefix}...) was already revoked at {_when(key.revoked_at)}")
        return 0
    key.revoked_at = time.time()
    session.commit()
    print(f"revoked {key.id} ({key.prefix}...)")
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the keys sub-command on the configured database (migrating it first)."""
    from sqlalchemy.orm import Session

    from pdeanim_service.settings import Settings
    from pdeanim_service.store.context import Store
    from pdeanim_service.store.tenants import issue_key

    if args.keys_command == "create":
        print(issue_key(Settings(), args.tenant))
        return 0
    store = Store.open(Settings(), run_migrations=True)
    try:
        # one write transaction from the start (BEGIN IMMEDIATE on SQLite): a read that later writes would
        # fail with "database is locked" when the running service committed in between
        with Session(store.engine.execution_options(immediate=True)) as session:
            if args.keys_command == "list":
                return _list(session, args)
            return _revoke(session, args)
    finally:
        store.close()
