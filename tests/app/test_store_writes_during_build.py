"""No write waits on a build (issue 28): a build held half way (on an Event, not a sleep) lets a DELETE, a
reservation and /readyz answer at once; the DELETE stops the build and holds; a killed build's scratch files go
at the next start; a build out of disk says so in its state."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import engine.store.shard as shard_module
import engine.store.store as store_module
from engine.build import job as build_job
from engine.build.job import BuildJob
from engine.scratch import SCRATCH_PREFIX, host_name
from engine.store.staging import leftover_ids, row_ids
from engine.store.store import CCSStore
from tests.app.conftest import synthetic_features, write_geojson


def _upload_job(store: Path, dataset: str, source: Path) -> BuildJob:
    params = {"elevation_field": "elevation", "interval": None, "source_scale": 50_000.0, "target_scale": 500_000.0}
    return BuildJob("upload", str(store), dataset, str(source), dataset, params, digest="d" * 64, workers=1)


@pytest.fixture()
def held_build(monkeypatch, client, tmp_path):
    """A build of 'mega' into the client's store, in a thread, held after its first shard is staged (in runs of
    two contours, each its own transaction) until ``release`` is set (``reached`` is set once it is held)."""
    store = Path(client.app.state.settings.store_path)
    reached, release = threading.Event(), threading.Event()
    monkeypatch.setattr(shard_module, "STAGE_CONTOURS", 2)
    real_merge = store_module.RowTally.merge

    def merge_then_wait(self, other):  # called once a shard's runs are committed: no lock is held here
        real_merge(self, other)
        if not reached.is_set():
            reached.set()
            assert release.wait(120)

    monkeypatch.setattr(store_module.RowTally, "merge", merge_then_wait)
    assert CCSStore(store).reserve("mega", 31)  # what an accepted upload holds
    source = write_geojson(tmp_path / "mega.geojson", synthetic_features(seed=3))
    result: dict[str, int] = {}
    thread = threading.Thread(target=lambda: result.setdefault("rc", build_job.run(_upload_job(store, "mega", source))))
    thread.start()
    try:
        assert reached.wait(300), "the build never reached its staged rows"
        yield store, release, thread, result
    finally:
        release.set()
        thread.join(120)


def _timed(call):
    started = time.perf_counter()
    answer = call()
    return answer, time.perf_counter() - started


def test_delete_reserve_and_readyz_answer_during_a_build_and_the_delete_holds(held_build, client):
    store, release, thread, result = held_build
    readyz, readyz_s = _timed(lambda: client.get("/readyz"))
    assert readyz.status_code == 503 and readyz_s < 1.0  # answers (not ready: 'mega' is building)
    assert any("mega" in p for p in readyz.json()["problems"])
    reserved, reserve_s = _timed(lambda: client.app.state.service.store.reserve("other", 1))
    assert reserved and reserve_s < 1.0  # an upload's reservation
    deleted, delete_s = _timed(lambda: client.delete("/datasets/mega"))
    assert deleted.status_code == 204 and delete_s < 1.0, deleted.text
    print(f"during the build: readyz {readyz_s * 1000:.0f} ms, reserve {reserve_s * 1000:.0f} ms, "
          f"DELETE {delete_s * 1000:.0f} ms")
    release.set()  # the build goes on: its next transaction finds it deleted and stops
    thread.join(120)
    assert not thread.is_alive() and result["rc"] == 0
    assert client.get("/datasets/mega").status_code == 404
    after = CCSStore(store)
    assert "mega" not in after.dataset_ids() and "mega" not in after.build_statuses()
    assert leftover_ids(after._con()) == []  # its staged rows are gone too
    assert after.integrity_ok()


def test_the_build_stores_the_dataset_when_nobody_deletes_it(held_build, client):
    store, release, thread, result = held_build
    held = CCSStore(store)
    staged = held._con().execute(
        "SELECT count(*) FROM contours WHERE dataset IN (?, ?)", row_ids("mega")
    ).fetchone()[0]
    assert staged > 0 and "mega" not in held.dataset_ids()  # staged rows are out of sight
    release.set()
    thread.join(120)
    assert result["rc"] == 0
    after = CCSStore(store)
    assert after.dataset("mega").n_contours == len(synthetic_features(seed=3))
    assert leftover_ids(after._con()) == [] and "mega" not in after.build_statuses()


def test_a_busy_store_answers_503_with_retry_after(client, monkeypatch):
    import engine.store.connection as connection

    monkeypatch.setattr(connection, "BUSY_TIMEOUT_S", 0.2)
    store = Path(client.app.state.settings.store_path)
    holder = CCSStore(store)._con()  # a new thread-local connection for the lock
    holder.execute("BEGIN IMMEDIATE")
    try:
        answer = client.delete("/datasets/hills")
    finally:
        holder.execute("ROLLBACK")
    assert answer.status_code == 503 and answer.headers["retry-after"]
    assert answer.json()["error"] == "store_busy"
    assert "hills" in CCSStore(store).dataset_ids()  # nothing half done


def test_scratch_of_a_dead_build_is_removed_at_start_and_a_live_ones_kept(tmp_path, built_store):
    from app.service import open_checked_store

    store = tmp_path / "ccsm.sqlite"
    store.write_bytes(built_store.read_bytes())
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{dead_pid}-abc.sqlite"
    live = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{os.getpid()}-abc.sqlite"
    stale.write_bytes(b"x")
    live.write_bytes(b"x")
    open_checked_store(store).close()
    assert not stale.exists() and live.exists()


def test_a_build_out_of_disk_says_so(client, tmp_path, monkeypatch):
    store = Path(client.app.state.settings.store_path)
    assert CCSStore(store).reserve("full", 31)

    def no_room(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(shard_module, "merge_run", no_room)
    source = write_geojson(tmp_path / "full.geojson", synthetic_features(seed=5))
    assert build_job.run(_upload_job(store, "full", source)) == 1
    status = CCSStore(store).build_statuses()["full"]
    assert status.state == "failed" and status.error.startswith("disk full: ")
    assert "No space left on device" in status.error
    assert leftover_ids(CCSStore(store)._con()) == []
