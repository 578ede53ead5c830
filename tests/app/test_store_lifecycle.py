"""The store across processes: first start builds the sample, a restart serves it at once, a killed build
changes nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import httpx
import numpy as np
import pytest

from engine.store.staging import staging_id
from engine.store.store import CCSStore
from tests.app.conftest import REPO, LiveServer, synthetic_features, write_geojson
from tests.app.helpers import check_tile, tile_for


@pytest.mark.slow
def test_sample_builds_on_first_start_and_restart_serves_from_store(tmp_path):
    store = tmp_path / "var" / "ccsm.sqlite"
    env = {"CCSM_STORE_PATH": str(store), "CCSM_BUILD_WORKERS": "2"}
    first = LiveServer(env, log=tmp_path / "first.log")
    try:
        first.wait_healthy()
        states = {d["id"]: d["state"] for d in httpx.get(first.url + "/datasets").json()}
        assert states["sample"] in ("building", "ready")
        info = first.wait_ready("sample", timeout=300)
        assert info["counts"]["contours"] == 1830
        z, x, y = tile_for(-84.2, 36.6, 12)
        tile = httpx.get(f"{first.url}/tiles/sample/{z}/{x}/{y}.mvt")
        assert tile.status_code == 200
        check_tile(tile.content)
    finally:
        first.stop()
    built_at = CCSStore(store).dataset("sample").built_at

    second = LiveServer(env, log=tmp_path / "second.log")
    try:
        second.wait_healthy()
        # Served at once: ready at the first request, from the stored rows (nothing rebuilt, see below).
        again = httpx.get(second.url + "/datasets/sample").json()
        assert again["state"] == "ready" and again["build"] is None
        assert again["data_version"] == info["data_version"]
        tile2 = httpx.get(f"{second.url}/tiles/sample/{z}/{x}/{y}.mvt")
        assert tile2.content == tile.content and tile2.headers["etag"] == tile.headers["etag"]
    finally:
        second.stop()
    stored = CCSStore(store)
    assert stored.dataset("sample").data_version == info["data_version"]
    assert stored.dataset("sample").built_at == built_at and stored.build_statuses() == {}


#: Run in the killed process: ``ccsm build`` with a page cache small enough that the new rows spill into the WAL
#: file, and a hook in the store's merge of the build's shards that, once KILL_AFTER_RUNS runs are merged (and
#: committed), merges one more and reports the WAL size inside that run's write transaction, then waits for the
#: kill.
KILLED_BUILD = """
import os, signal, sys
import engine.store.shard as sh
import engine.store.store as sq
from pathlib import Path
from app.cli import main

after = int(os.environ["KILL_AFTER_RUNS"])
wal = Path(os.environ["STORE"] + "-wal")
real_save, real_merge = sq.CCSStore.save, sh.merge_run
seen = {"runs": 0, "wal_before": 0}

def save(self, *a, **k):
    self._con().execute("PRAGMA cache_size=8")
    seen["wal_before"] = wal.stat().st_size if wal.exists() else 0
    return real_save(self, *a, **k)

def merge(*a):
    real_merge(*a)
    if seen["runs"] == after:
        print("inside the write", after, seen["wal_before"], wal.stat().st_size, flush=True)
        signal.pause()
    seen["runs"] += 1

sq.CCSStore.save, sh.merge_run = save, merge
sh.STAGE_CONTOURS = 8  # runs of a few contours: the small source's build commits some before the kill
sys.argv = ["ccsm", *sys.argv[1:]]
main()
"""


@pytest.mark.slow
def test_killed_build_leaves_the_store_as_it_was(tmp_path, built_store):
    store = tmp_path / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    before = CCSStore(store).dataset("hills")
    fids_before = CCSStore(store).all_fids("hills")
    recs_before = CCSStore(store).load(fids_before)
    other = write_geojson(tmp_path / "other.geojson", synthetic_features(seed=11))
    # Rebuild dataset 'hills' from another source and kill -9 the build inside the store's write transaction.
    cmd = [sys.executable, "-c", KILLED_BUILD, "build", str(other), "--store", str(store), "--id", "hills"]
    proc = subprocess.Popen(
        [*cmd, "--workers", "1"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=(tmp_path / "build.log").open("wb"),
        env={**os.environ, "STORE": str(store), "KILL_AFTER_RUNS": "1"},
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().decode().split()
        assert line[:3] == ["inside", "the", "write"], (tmp_path / "build.log").read_text()[-2000:]
        wal_before, wal_now = int(line[4]), int(line[5])
        assert wal_now > wal_before  # a run of new rows is on disk, uncommitted
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    after = CCSStore(store)
    assert after.integrity_ok()
    info = after.dataset("hills")
    assert info.data_version == before.data_version
    assert info.source_hash == before.source_hash
    assert info.n_contours == before.n_contours
    assert after.all_fids("hills") == fids_before
    assert after.query("hills", info.bounds_3857) == fids_before
    for old, new in zip(recs_before, after.load(fids_before), strict=True):
        assert new.contour_id == old.contour_id and np.array_equal(new.base, old.base)
        assert np.array_equal(new.top, old.top) and np.array_equal(new.original, old.original)
    # The run merged and committed before the kill waits under the build's private staging id, and nothing
    # else of the build is anywhere: not under the dataset's own id, not under the live version's rows.
    con = after._con()
    live = con.execute("SELECT rows_id FROM datasets WHERE id = 'hills'").fetchone()[0]
    held = dict(con.execute("SELECT dataset, count(*) FROM contours GROUP BY dataset").fetchall())
    assert held.pop(live) == before.n_contours
    assert list(held) == [staging_id("hills", live)] and held[staging_id("hills", live)] > 0, held


def test_build_command_is_idempotent(tmp_path, synthetic_path):
    store = tmp_path / "s.sqlite"
    cmd = [
        sys.executable,
        "-c",
        "from app.cli import main; main()",
        "build",
        str(synthetic_path),
        "--store",
        str(store),
        "--id",
        "hills",
        "--workers",
        "1",
    ]
    one = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    assert one.returncode == 0, one.stderr
    assert "built hills" in one.stderr
    two = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    assert "already current" in two.stderr
    bad = subprocess.run(
        cmd[:4] + [str(tmp_path / "missing.geojson"), "--store", str(store)],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2
    assert CCSStore(store).dataset("hills").data_version == 1
