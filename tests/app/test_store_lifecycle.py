"""The store across processes: first start builds the sample, a restart serves it at once, a killed build
changes nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import httpx
import pytest

from engine.io.source import sample_contours_path
from engine.store.sqlite import CCSStore
from tests.app.conftest import REPO, LiveServer
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

    second = LiveServer(env, log=tmp_path / "second.log")
    try:
        second.wait_healthy()
        t0 = time.monotonic()
        again = httpx.get(second.url + "/datasets/sample").json()
        assert again["state"] == "ready" and again["build"] is None
        assert again["data_version"] == info["data_version"]
        tile2 = httpx.get(f"{second.url}/tiles/sample/{z}/{x}/{y}.mvt")
        assert tile2.content == tile.content and tile2.headers["etag"] == tile.headers["etag"]
        assert time.monotonic() - t0 < 5
    finally:
        second.stop()
    assert CCSStore(store).dataset("sample").data_version == info["data_version"]


@pytest.mark.slow
def test_killed_build_leaves_the_store_as_it_was(tmp_path, built_store):
    store = tmp_path / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    before = CCSStore(store).dataset("hills")
    fids_before = CCSStore(store).all_fids("hills")
    # Rebuild dataset 'hills' from another, larger source, and kill -9 the build half way.
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from app.cli import main; main()",
            "build",
            str(sample_contours_path()),
            "--store",
            str(store),
            "--id",
            "hills",
            "--workers",
            "1",
        ],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env={**os.environ, "COLUMNS": "100"},
    )
    assert proc.stdout is not None
    line = proc.stdout.readline().decode()
    assert "building hills" in line
    time.sleep(3.0)
    assert proc.poll() is None, "the build finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    after = CCSStore(store)
    assert after.integrity_ok()
    info = after.dataset("hills")
    assert info.data_version == before.data_version
    assert info.source_hash == before.source_hash
    assert info.n_contours == before.n_contours
    assert after.all_fids("hills") == fids_before
    assert len(after.query("hills", info.bounds_3857)) == len(fids_before)


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
