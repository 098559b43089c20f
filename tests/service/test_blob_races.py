"""Uploads, dedup and deletes raced across tenants, on SQLite + local blobs and on PostgreSQL + S3 (moto):
every acknowledged upload (its row committed: the route's 201) keeps its blob until its own delete, a poses
upload whose mesh went is refused with nothing left behind, and after every round the stored blobs are
exactly the ones some row names (so the sweeper finds no orphan either).

Each round races a few operations on a pool of three contents shared by three tenants (so most uploads
dedup onto a blob another tenant's row names):

- *stepped* rounds run the operations' steps in a random order in one thread, which reaches every order of
  "store the bytes", "commit the row", "delete the rows" and "release the blobs" (the race of the audit:
  a delete releasing the blob between another tenant's store and commit);
- *threaded* rounds run the same operations at once in threads (real lock waits), with the sweeper among
  them at a grace of 0 s, which removes every blob no row names yet.

The routes call the same functions: ``put_file`` then ``add_row`` (meshes), ``put_file`` then
``commit_poses`` (poses), ``delete_mesh``; ``tests/service/test_upload_races.py`` checks the routes
themselves."""

from __future__ import annotations

import os
import random
import tempfile
import threading
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from pdeanim_service.api.routes.poses import commit_poses
from pdeanim_service.store import lifecycle
from pdeanim_service.store.blobrefs import add_row, named, release, sweep
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Mesh
from pdeanim_service.store.tenants import create_key

CONTENTS = [f"shared content {i}\n".encode() * (i + 1) for i in range(3)]
TENANTS = ["ann", "bob", "cyd"]
CI_ROUNDS = {"sqlite": 300, "postgres": 100}  # PostgreSQL + S3 (moto) rounds take about 5x longer
BENCH_ROUNDS = 10_000


@dataclass
class World:
    """The store, the tenants, and what was acknowledged and not deleted yet (id -> (tenant, key, bytes))."""

    store: Store
    tmp: Path
    tenants: dict[str, str] = field(default_factory=dict)
    meshes: dict[str, tuple[str, str, bytes]] = field(default_factory=dict)
    poses: dict[str, tuple[str, str, bytes]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    counts: dict[str, int] = field(default_factory=dict)

    def count(self, what: str) -> None:
        with self.lock:
            self.counts[what] = self.counts.get(what, 0) + 1

    def source(self, data: bytes) -> Path:
        """A file holding ``data``, as the upload's scratch file (the caller removes it)."""
        fd, path = tempfile.mkstemp(dir=self.tmp)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        return Path(path)


def upload_mesh(w: World, tenant: str, data: bytes) -> Iterator[None]:
    """The mesh route after validation: store the bytes, then the row under the blob's lock."""
    src = w.source(data)
    try:
        key = w.store.blobs.put_file(src)
        yield
        row = Mesh(tenant_id=w.tenants[tenant], filename="m.obj", blob_key=key, n_vertices=4, n_faces=4,
                   stats={})
        add_row(w.store, row, {key: src})
    finally:
        src.unlink(missing_ok=True)
    with w.lock:  # acknowledged: the route answers 201 now
        w.meshes[row.id] = (tenant, key, data)
    w.count("mesh 201")


def upload_poses(w: World, tenant: str, mesh_id: str, data: bytes) -> Iterator[None]:
    """The poses route after validation: store the bytes, then the row if the mesh is still there."""
    mesh = Mesh(id=mesh_id, tenant_id=w.tenants[tenant], n_vertices=4)
    src = w.source(data)
    try:
        key = w.store.blobs.put_file(src)
        yield
        row = commit_poses(w.store, key, src, w.tenants[tenant], mesh, 2, {})
    finally:
        src.unlink(missing_ok=True)
    if row is None:
        w.count("poses 404")
        return
    with w.lock:  # acknowledged, unless its mesh's delete already took it along
        if mesh_id in w.meshes:
            w.poses[row.id] = (mesh_id, key, data)
    w.count("poses 201")


def delete_mesh(w: World, tenant: str, mesh_id: str) -> Iterator[None]:
    """DELETE /v1/meshes/{id}: the rows in one transaction, then (a later step) the blobs they named."""
    gone = lifecycle.delete_mesh_rows(w.store, mesh_id, w.tenants[tenant])
    with w.lock:  # the rows are gone: from here on nobody may expect these to be readable
        w.meshes.pop(mesh_id, None)
        for poses_id in [p for p, (m, _, _) in w.poses.items() if m == mesh_id]:
            w.poses.pop(poses_id)
    yield
    if gone is not None:
        release(w.store, gone.keys)
    w.count("delete")


def sweeper(w: World) -> Iterator[None]:
    """The sweeper at a grace of 0: removes every blob that no row names at the moment it looks."""
    yield
    sweep(w.store, 0.0, now=time.time() + 1.0)
    w.count("sweep")


def _ops(w: World, rng: random.Random, n: int, with_sweeper: bool) -> list[Iterator[None]]:
    """``n`` random operations on the world as it is (deletes and poses only of acknowledged meshes)."""
    ops, taken = [], set()
    for _ in range(n):
        live = [m for m in w.meshes if m not in taken]
        pick = rng.random() * (0.5 if len(live) > 6 else 1.0)  # keep a handful alive: checks stay cheap
        if live and pick < 0.35:
            mesh_id = rng.choice(live)
            taken.add(mesh_id)
            ops.append(delete_mesh(w, w.meshes[mesh_id][0], mesh_id))
        elif live and pick < 0.5:
            mesh_id = rng.choice(live)
            ops.append(upload_poses(w, w.meshes[mesh_id][0], mesh_id, rng.choice(CONTENTS)))
        else:
            ops.append(upload_mesh(w, rng.choice(TENANTS), rng.choice(CONTENTS)))
    if with_sweeper:
        ops.append(sweeper(w))
    return ops


def run_stepped(ops: list[Iterator[None]], rng: random.Random) -> None:
    """Advance the operations one step at a time, in a random order, until all are done."""
    pending = list(ops)
    while pending:
        op = rng.choice(pending)
        try:
            next(op)
        except StopIteration:
            pending.remove(op)


def run_threaded(ops: list[Iterator[None]]) -> None:
    """Run the operations at once, one thread each, all released by one barrier."""
    barrier, errors = threading.Barrier(len(ops)), []

    def run(op: Iterator[None]) -> None:
        try:
            barrier.wait(30)
            for _ in op:
                pass
        except BaseException:  # noqa: BLE001 - reported by the test below
            errors.append(traceback.format_exc())

    threads = [threading.Thread(target=run, args=(op,)) for op in ops]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    if errors:
        pytest.fail("\n".join(errors), pytrace=False)
    assert not any(t.is_alive() for t in threads), "an operation hung"


def check(w: World, full: bool) -> None:
    """Every acknowledged, undeleted upload is readable (bytes compared when ``full``), and the store holds
    exactly the blobs some row names."""
    for kind, rows in (("mesh", w.meshes), ("poses", w.poses)):
        for row_id, (_, key, data) in rows.items():
            if full:
                assert w.store.blobs.get(key) == data, (kind, row_id, key)
            else:
                assert w.store.blobs.exists(key), f"acknowledged {kind} {row_id} lost its blob {key}"
    stored = set(w.store.blobs.keys(time.time() + 3600))
    with w.store.sessions() as s:
        assert named(s, sorted(stored)) == stored, f"blobs no row names: {stored - named(s, sorted(stored))}"
        expected = {k for _, k, _ in [*w.meshes.values(), *w.poses.values()]}
        assert expected <= stored


@pytest.fixture
def world(backend, tmp_path) -> Iterator[World]:
    store = Store.open(backend.settings(), run_migrations=True)
    w = World(store, tmp_path)
    with store.sessions() as s:
        for name in TENANTS:
            _, tenant = create_key(s, name)
            w.tenants[name] = tenant.id
        s.commit()
    yield w
    store.close()


def race(w: World, rounds: int, seed: int = 34, every: int = 0) -> dict[str, int]:
    """``rounds`` raced rounds (alternately stepped and threaded), checked after each (a progress line every
    ``every`` rounds when set); then everything is deleted and swept, and the store must be empty."""
    rng, started = random.Random(seed), time.perf_counter()
    for i in range(rounds):
        if every and i and i % every == 0:
            print(f"{i} rounds checked in {time.perf_counter() - started:.0f} s: {w.counts}", flush=True)
        threaded = i % 2 == 1
        ops = _ops(w, rng, rng.randint(2, 4), with_sweeper=threaded or rng.random() < 0.2)
        if threaded:
            run_threaded(ops)
        else:
            run_stepped(ops, rng)
        check(w, full=i % 25 == 0)
    for mesh_id, (tenant, _, _) in list(w.meshes.items()):
        for _ in delete_mesh(w, tenant, mesh_id):
            pass
    sweep(w.store, 0.0, now=time.time() + 1.0)
    assert list(w.store.blobs.keys(time.time() + 3600)) == [] and not w.meshes and not w.poses
    return w.counts


def test_no_acknowledged_upload_is_lost_in_raced_rounds(world, backend_kind):
    rounds = CI_ROUNDS[backend_kind]
    counts = race(world, rounds)
    # the races happened: uploads deduplicated onto blobs that deletes released, poses lost their mesh
    assert counts["mesh 201"] > rounds / 2 and counts["delete"] > rounds / 4, counts
    assert counts.get("poses 404", 0) > 0 and counts.get("poses 201", 0) > 0, counts


@pytest.mark.slow
@pytest.mark.timeout(4 * 3600)  # 0.05-0.4 s a round on SQLite, about 4x that on PostgreSQL + S3 (moto)
def test_no_acknowledged_upload_is_lost_in_ten_thousand_rounds(world, capsys):
    started = time.perf_counter()
    with capsys.disabled():
        counts = race(world, BENCH_ROUNDS, seed=2026, every=1000)
        print(f"\n{BENCH_ROUNDS} raced rounds in {time.perf_counter() - started:.1f} s: {counts}; 0 lost, "
              "0 orphan blobs")


def test_the_sweeper_keeps_named_young_and_intermediate_blobs(world, monkeypatch, capsys):
    store, now = world.store, time.time()
    for _ in upload_mesh(world, "ann", CONTENTS[0]):
        pass
    named_key = next(iter(world.meshes.values()))[1]
    orphan, young = store.blobs.put(b"left by a killed process"), store.blobs.put(b"being committed")
    intermediate = store.blobs.put(b"a window's frames", key="windowed/job_x/frames.f32")
    old = now - 7200
    if store.settings.resolved_blob_url().startswith("file://"):  # S3 keeps its own times: age them here only
        for key in (orphan, named_key, intermediate):
            os.utime(store.blobs._path(key), (old, old))  # noqa: SLF001
        kept = {named_key, young, intermediate}
        out = sweep(store, grace_seconds=3600)
    else:
        kept = {named_key, intermediate}
        out = sweep(store, grace_seconds=0, now=time.time() + 5)  # S3 keeps whole seconds
    assert out.removed == len({orphan, young} - kept), out
    assert {k for k in (orphan, young, named_key, intermediate) if store.blobs.exists(k)} == kept
    monkeypatch.setenv("PDEANIM_DATA_DIR", str(store.settings.data_dir))
    for name, value in world_env(store).items():
        monkeypatch.setenv(name, value)
    from pdeanim_service.cli import main

    assert main(["blobs", "sweep", "--grace", "0"]) == 0  # the command: same settings, one sweep, JSON
    assert '"removed"' in capsys.readouterr().out
    assert store.blobs.exists(named_key) and store.blobs.exists(intermediate)
    assert not store.blobs.exists(young)


def world_env(store: Store) -> dict[str, str]:
    """The PDEANIM_* variables of ``store``'s settings (for the command run in this process)."""
    s = store.settings
    env = {"PDEANIM_DATABASE_URL": s.resolved_database_url(), "PDEANIM_BLOB_URL": s.resolved_blob_url()}
    if s.s3_endpoint_url:
        env["PDEANIM_S3_ENDPOINT_URL"] = s.s3_endpoint_url
    return env
