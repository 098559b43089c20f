"""Backends for the service tests: the embedded default (SQLite + local blobs) and, as a second run of the
same tests, PostgreSQL (``pgserver``: 127.0.0.1:5432, or a throwaway cluster the tests start; a database
created and dropped per test or module) with S3 on moto's server. Under CI a missing PostgreSQL fails."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from pdeanim_service.launcher import free_port
from pdeanim_service.settings import Settings

from ..ci import missing
from .pgserver import PgServer, start_or_find


@dataclass
class Backend:
    """Environment variables selecting one backend; ``settings()`` builds the same in-process."""

    name: str
    env: dict[str, str] = field(default_factory=dict)

    def settings(self, **overrides) -> Settings:
        values = {
            k.removeprefix("PDEANIM_").lower(): v for k, v in self.env.items() if k.startswith("PDEANIM_")
        }
        return Settings(**{**values, **overrides})


@pytest.fixture(scope="session")
def pg_server() -> Iterator[PgServer]:
    """The PostgreSQL server for the session (found or started); a failure under CI when there is none."""
    server, reason = start_or_find()
    if server is None:
        missing(reason)
    yield server
    server.stop()


def _admin(server: PgServer, sql: str) -> None:
    import psycopg

    with psycopg.connect(server.dsn(), autocommit=True) as conn:
        conn.execute(sql)


@pytest.fixture(scope="session")
def s3_server():
    """moto's S3 server on a free loopback port, with dummy credentials in the environment."""
    from moto.server import ThreadedMotoServer

    for k, v in {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing",
                 "AWS_DEFAULT_REGION": "us-east-1"}.items():
        os.environ.setdefault(k, v)
    port = free_port()
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    yield f"http://127.0.0.1:{port}"
    server.stop()


def _make_bucket(endpoint: str, name: str) -> None:
    import boto3

    boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1").create_bucket(Bucket=name)


@pytest.fixture(scope="session", params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def backend_kind(request) -> str:
    return request.param


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The PostgreSQL run of a module that tests HTTP routes over the store (``POSTGRES_NIGHTLY = True``) is
    marked slow: CI runs those routes on SQLite, and the store, queue, worker, deletion and scale-out tests on
    both backends; script/test-nightly runs the routes on PostgreSQL too. Modules whose PostgreSQL run only
    repeats what SQLite shows (process lifecycle, window tasks through the job route, the CLI, upload
    fairness) are marked the same way to keep CI's time."""
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if params.get("backend_kind") == "postgres" and getattr(item.module, "POSTGRES_NIGHTLY", False):
            item.add_marker(pytest.mark.slow)


@contextmanager
def open_backend(kind: str, data_dir: Path, request) -> Iterator[Backend]:
    """An empty backend: its own data dir, and on PostgreSQL its own database and bucket (dropped after)."""
    env = {"PDEANIM_DATA_DIR": str(data_dir)}
    if kind == "sqlite":
        yield Backend("sqlite", env)
        return
    pg = request.getfixturevalue("pg_server")
    endpoint = request.getfixturevalue("s3_server")
    name = f"pdeanim_test_{uuid.uuid4().hex[:12]}"
    _admin(pg, f"CREATE DATABASE {name}")
    _make_bucket(endpoint, name.replace("_", "-"))
    env.update(
        {
            "PDEANIM_DATABASE_URL": pg.url(name),
            "PDEANIM_BLOB_URL": f"s3://{name.replace('_', '-')}/blobs",
            "PDEANIM_S3_ENDPOINT_URL": endpoint,
            "AWS_ACCESS_KEY_ID": "testing",
            "AWS_SECRET_ACCESS_KEY": "testing",
            "AWS_DEFAULT_REGION": "us-east-1",
        }
    )
    try:
        yield Backend("postgres", env)
    finally:
        _admin(pg, f"DROP DATABASE IF EXISTS {name} WITH (FORCE)")


@pytest.fixture
def backend(backend_kind, tmp_path: Path, request) -> Iterator[Backend]:
    """A fresh backend per test."""
    with open_backend(backend_kind, tmp_path / "data", request) as b:
        yield b


@pytest.fixture(scope="module")
def module_backend(backend_kind, tmp_path_factory, request) -> Iterator[Backend]:
    """A backend shared by the tests of one module (one server and its workers)."""
    with open_backend(backend_kind, tmp_path_factory.mktemp("data"), request) as b:
        yield b


def running_services(backend: Backend, data_dir: Path, env_extra: dict[str, str] | None = None,
                     server_args: tuple[str, ...] = ()) -> Iterator:
    """A module's server and one job worker on ``backend`` (extra settings in ``env_extra``), stopped
    after."""
    from .harness import Services

    svc = Services(backend, data_dir, env_extra=env_extra or {})
    svc.start_server(*server_args)
    svc.start_worker()
    yield svc
    svc.stop()


@pytest.fixture(scope="module")
def api(services):
    """A client of the module's ``services`` with tenant alice's key."""
    from .harness import client, make_key

    with client(services, make_key(services.backend, "alice")) as c:
        yield c


@pytest.fixture(scope="module")
def other(services):
    """A client of the module's ``services`` with another tenant's key (mallory)."""
    from .harness import client, make_key

    with client(services, make_key(services.backend, "mallory")) as c:
        yield c
