"""Replicas switch to a new store atomically (issue 12 item 4): ``ccsm serve --workers 2`` on a store link, under
load, while ``ccsm build --publish`` points the link at a new build."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import pytest
from conftest import LAT0, LON0, REPO, LiveServer
from helpers import tile_for

from engine.errors import StoreError
from engine.store.store import CCSStore
from engine.store.switch import StorePointer, publish

#: Tiles around the synthetic hills at z12 to z14 (most hold contours) and one metadata path.
PATHS = [
    "/tiles/hills/{}/{}/{}.mvt".format(*tile_for(LON0 + dx, LAT0 + dy, z))
    for z in (12, 13, 14)
    for dx in (-0.02, 0.02)
    for dy in (-0.02, 0.02)
] + ["/datasets/hills"]


def copy_store(built: Path, to: Path) -> Path:
    CCSStore(built)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    shutil.copyfile(built, to)
    return to


def hammer(url: str, stop: threading.Event, seen: Counter[str], lock: threading.Lock) -> None:
    """Request PATHS in turn until ``stop``; count each status (and each failure to get one)."""
    with httpx.Client(base_url=url, timeout=30) as client:
        k = 0
        while not stop.is_set():
            path = PATHS[k % len(PATHS)]
            k += 1
            try:
                outcome = str(client.get(path).status_code)
            except httpx.HTTPError as exc:
                outcome = type(exc).__name__
            with lock:
                seen[outcome] += 1


@pytest.mark.slow
def test_replicas_switch_under_load(tmp_path: Path, built_store: Path, synthetic_path: Path) -> None:
    old = copy_store(built_store, tmp_path / "v1.sqlite")
    new = copy_store(built_store, tmp_path / "v2.sqlite")
    live = tmp_path / "live.sqlite"
    publish(live, old)
    server = LiveServer(
        {"CCSM_STORE_PATH": str(live), "CCSM_SERVE_SAMPLE": "false", "CCSM_BUILD_ON_START": "false"},
        args=["--workers", "2"],
        log=tmp_path / "serve.log",
    )
    stop, lock, seen = threading.Event(), threading.Lock(), Counter[str]()
    threads = [threading.Thread(target=hammer, args=(server.url, stop, seen, lock)) for _ in range(4)]
    try:
        server.wait_healthy(timeout=180)  # the machine is shared: two workers may start slowly
        assert httpx.get(server.url + "/datasets/extra").status_code == 404
        for thread in threads:
            thread.start()
        time.sleep(1.0)
        # The new build adds a dataset to v2 and publishes it while the replicas are under load.
        build = subprocess.run(
            [sys.executable, "-c", "from app.cli import main; main()", "build", str(synthetic_path),
             "--id", "extra", "--store", str(new), "--publish", str(live), "--workers", "1"],
            cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert build.returncode == 0, build.stderr
        assert os.path.realpath(live) == str(new)
        # Both workers answer from the new store within a moment (each looks at the link every 0.25 s).
        answers = [httpx.get(server.url + "/datasets/extra").status_code for _ in range(40)]
        assert answers[-20:] == [200] * 20, answers
        time.sleep(1.0)
    finally:
        stop.set()
        for thread in threads:
            thread.join(60) if thread.ident else None
        server.stop()
    assert sum(seen.values()) > 40, seen
    assert set(seen) <= {"200", "204"} and seen["200"] > 20, f"requests that failed during the switch: {seen}"


def test_publish_refuses_a_plain_file_and_a_missing_store(tmp_path: Path, built_store: Path) -> None:
    plain = copy_store(built_store, tmp_path / "plain.sqlite")
    other = copy_store(built_store, tmp_path / "other.sqlite")
    with pytest.raises(StoreError, match="plain file, not a link"):
        publish(plain, other)
    assert plain.is_file() and not plain.is_symlink()  # left as it was
    with pytest.raises(StoreError, match="no such store file"):
        publish(tmp_path / "live.sqlite", tmp_path / "missing.sqlite")
    assert not (tmp_path / "live.sqlite").exists()


def test_pointer_sees_the_link_move(tmp_path: Path, built_store: Path) -> None:
    a = copy_store(built_store, tmp_path / "a.sqlite")
    b = copy_store(built_store, tmp_path / "b.sqlite")
    live = tmp_path / "live.sqlite"
    publish(live, a)
    pointer = StorePointer(live)
    assert pointer.follows and pointer.target == a
    time.sleep(0.3)
    assert pointer.moved() is None
    publish(live, b)
    time.sleep(0.3)
    assert pointer.moved() == b
    assert pointer.moved() is None  # reported once
