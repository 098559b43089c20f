"""Fast checks without servers: OpenAPI drift, docker-compose.yml, settings, the clip cache, ETags."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from pdeanim_service.api.cache import CachedClip, ClipCache
from pdeanim_service.api.openapi import DEFAULT_PATH, openapi_text
from pdeanim_service.settings import Settings
from pdeanim_service.store.queue import QueuePolicy

from ..ci import missing

ROOT = Path(__file__).resolve().parents[2]


def test_openapi_file_matches_the_app():
    assert DEFAULT_PATH.read_text() == openapi_text(), (
        "openapi/openapi.json drifted: python -m pdeanim_service.api.openapi"
    )


def test_openapi_operation_ids_are_stable_and_errors_share_one_shape():
    import json

    doc = json.loads(openapi_text())
    ops = {op["operationId"] for methods in doc["paths"].values() for op in methods.values()}
    assert ops == {
        "healthz",
        "uploadMesh",
        "getMesh",
        "getMeshTopology",
        "getMeshFile",
        "uploadPoses",
        "getPoses",
        "createJob",
        "getJob",
        "getClip",
        "getClipCoefficients",
        "getClipCoefficientsWindow",
        "getClipTopology",
        "getClipFrame",
        "getClipAnimation",
        "headClipAnimation",
        "getExport",
        "listMeshes",
        "listPoses",
        "listClips",
        "listJobs",
        "deleteMesh",
        "deleteClip",
        "cancelJob",
    }
    assert "HTTPValidationError" not in doc["components"]["schemas"]
    # typed job bodies: a union discriminated on kind, option models generated from the library's dataclasses
    body = doc["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert set(body["discriminator"]["mapping"]) == {"simulate", "fit", "cyclic", "export"}
    schemas = doc["components"]["schemas"]
    assert {"frames", "young", "target_tets"} <= set(schemas["SceneParams"]["properties"])
    assert {"segments", "target_rel_rms"} <= set(schemas["FitOptions"]["properties"])
    assert {"mode", "n_curves", "amplitude"} <= set(schemas["CyclicOptions"]["properties"])
    for path, methods in doc["paths"].items():  # every route documents what the request guard may answer
        for method, op in methods.items():
            assert {"413", "431"} <= set(op["responses"]), (method, path)


def test_docker_compose_file_is_valid():
    if shutil.which("docker-compose") is None:
        missing("docker-compose is not installed (script/setup installs it with apt-get)")
    out = subprocess.run(["docker-compose", "-f", str(ROOT / "docker-compose.yml"), "config", "-q"],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr


def test_settings_defaults_and_environment(tmp_path, monkeypatch):
    s = Settings(data_dir=tmp_path)
    assert s.resolved_database_url() == f"sqlite:///{tmp_path / 'pdeanim.sqlite3'}"
    assert s.resolved_blob_url() == f"file://{tmp_path / 'blobs'}"
    monkeypatch.setenv("PDEANIM_DATABASE_URL", "postgresql+psycopg://u@h/db")
    monkeypatch.setenv("PDEANIM_MAX_ATTEMPTS", "7")
    s = Settings()
    assert s.resolved_database_url() == "postgresql+psycopg://u@h/db" and s.max_attempts == 7
    monkeypatch.setenv("PDEANIM_MAX_ATTEMPTS", "0")
    with pytest.raises(ValueError):
        Settings()


def test_backoff_doubles_up_to_the_cap():
    p = QueuePolicy(backoff_seconds=2, backoff_max_seconds=10)
    assert [p.backoff(n) for n in (1, 2, 3, 4)] == [2, 4, 8, 10]


def test_clip_cache_is_a_bounded_lru():
    cache, loads = ClipCache(2), []

    def loader(name):
        def load():
            loads.append(name)
            return CachedClip("t", name, name, object(), object())
        return load

    for name in ("a", "b", "a", "c", "b"):
        cache.get(name, loader(name))
    assert loads == ["a", "b", "c", "b"] and len(cache) == 2


def test_etag_matching():
    from starlette.requests import Request

    from pdeanim_service.api.httpcache import etag_matches

    def req(value):
        return Request({"type": "http", "headers": [(b"if-none-match", value.encode())]})

    assert etag_matches(req('"x", "abc"'), '"abc"') and etag_matches(req("*"), '"abc"')
    assert etag_matches(req('W/"abc"'), '"abc"') and not etag_matches(req('"abd"'), '"abc"')


def test_healthz_503_has_the_error_shape(tmp_path):
    """A database without its jobs table (a real fault: the table dropped behind the service's back) makes
    /healthz answer 503 in the one error shape, naming the part that fails."""
    import sqlite3

    from fastapi.testclient import TestClient

    from pdeanim_service.api.app import create_app
    from pdeanim_service.store.context import Store

    settings = Settings(data_dir=tmp_path)
    store = Store.open(settings, run_migrations=True)
    try:
        with TestClient(create_app(settings, store=store)) as client:
            assert client.get("/healthz").json() == {"status": "ok", "database": "ok", "blobs": "ok"}
            with sqlite3.connect(settings.resolved_database_url().removeprefix("sqlite:///")) as db:
                db.execute("DROP TABLE jobs")
            r = client.get("/healthz")
        assert r.status_code == 503
        body = r.json()
        assert set(body) == {"error"} and body["error"]["code"] == "unavailable"
        assert body["error"]["message"].startswith("database: error: ") and "jobs" in body["error"]["message"]
        assert "blobs" not in body["error"]["message"]
    finally:
        store.close()
