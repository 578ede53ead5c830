"""Issue 10: a plain tile never waits behind a morph tile (a real server on loopback).

Morph tiles run their crossing check per tile, up to half a second on a dense tile, so they have a lane of
their own (``CCSM_MORPH_RENDER_WORKERS``, app/render/pool.py). Here the one morph worker is stopped
(SIGSTOP) in the middle of a morph request, the slowest morph tile there can be: the morph request waits, a
plain tile is answered meanwhile, and the morph request is answered once its worker goes on.

The plain tile's bound (10 s) is a behaviour bound, not a speed claim: a plain tile queued behind the stopped
worker waits for the 20 s deadline of the morph request.
"""

from __future__ import annotations

import os
import shutil
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import psutil
import pytest
from support.processes import forked_processes

from engine.store.store import CCSStore
from tests.app.conftest import LAT0, LON0, LiveServer
from tests.app.helpers import tile_for

PLAIN_BOUND_S = 10.0


@pytest.fixture(scope="module")
def server(built_store: Path, synthetic_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One light, one morph and one heavy worker; no morph cache, so every morph request reaches the worker."""
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    folder = tmp_path_factory.mktemp("morph-lane")
    store = folder / "ccsm.sqlite"
    shutil.copy(built_store, store)
    env = {
        "CCSM_STORE_PATH": str(store),
        "CCSM_SOURCES": str(synthetic_path),
        "CCSM_RENDER_WORKERS": "1",
        "CCSM_MORPH_RENDER_WORKERS": "1",
        "CCSM_HEAVY_RENDER_WORKERS": "1",
        "CCSM_MORPH_CACHE_MB": "0",
        "CCSM_REQUEST_TIMEOUT_S": "20",
    }
    live = LiveServer(env, log=folder / "server.log")
    try:
        live.wait_healthy(120)
        live.wait_ready("hills")
        yield live
    finally:
        live.stop()


def render_workers(server: LiveServer) -> list[psutil.Process]:
    """The server's render workers: the children of its fork server."""
    return forked_processes(server.proc.pid)


def cpu_seconds(workers: list[psutil.Process]) -> dict[int, float]:
    return {w.pid: sum(w.cpu_times()[:2]) for w in workers}


def morph_worker(server: LiveServer) -> psutil.Process:
    """The worker that draws morph tiles: the one whose CPU time grows while morph tiles (and nothing else)
    are drawn (each request a new tile)."""
    workers = render_workers(server)
    assert len(workers) == 3
    before = cpu_seconds(workers)
    for z in range(8, 15):
        for dx in (-1, 0, 1):
            _, x, y = tile_for(LON0, LAT0, z)
            assert httpx.get(f"{server.url}/morph/hills/{z}/{x + dx}/{y}.mvt", timeout=60).status_code in (200, 204)
    grown = {pid: t - before[pid] for pid, t in cpu_seconds(workers).items()}
    busiest = max(grown, key=lambda pid: grown[pid])
    assert grown[busiest] > 0 and sorted(grown.values())[-2] == 0, grown  # one worker drew them all
    return next(w for w in workers if w.pid == busiest)


def test_a_plain_tile_is_answered_while_the_morph_worker_is_stuck(server):
    worker = morph_worker(server)
    z, x, y = tile_for(LON0, LAT0, 12)
    morph: dict[str, object] = {}

    def ask_morph() -> None:
        morph["response"] = httpx.get(f"{server.url}/morph/hills/{z}/{x}/{y}.mvt", timeout=60)

    worker.send_signal(signal.SIGSTOP)
    try:
        thread = threading.Thread(target=ask_morph)
        thread.start()
        time.sleep(0.5)  # the morph request has reached the stopped worker
        plain = httpx.get(f"{server.url}/tiles/hills/{z}/{x}/{y}.mvt", timeout=PLAIN_BOUND_S)
        assert plain.status_code == 200 and plain.content
        assert thread.is_alive() and "response" not in morph  # the morph request still waits on its worker
    finally:
        worker.send_signal(signal.SIGCONT)
    thread.join()
    r = morph["response"]
    assert isinstance(r, httpx.Response) and r.status_code == 200 and r.content
    assert worker.is_running()  # the worker went on and answered; it was not replaced


def test_background_workers_take_the_idle_scheduling_class(server):
    """Map tiles' workers (light and morph lanes) stay in the normal class at niceness +5; the heavy lane runs
    in Linux's idle class, so it gives a core up the moment a map tile's worker wants it."""
    workers = render_workers(server)
    own = psutil.Process(server.proc.pid).nice()
    classes = sorted((w.nice() - own, os.sched_getscheduler(w.pid)) for w in workers)
    assert classes == [(5, os.SCHED_OTHER), (5, os.SCHED_OTHER), (10, os.SCHED_IDLE)], classes
