"""``ccsm build --scheduler``: a real Dask scheduler and two workers on loopback build the same tiles as a local
build (issue 12 item 3)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from support.processes import stop_process
from synthetic_rasters import fractal_heights, write_geotiff

from engine.serve.renderer import Renderer
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds
from tests.app.conftest import REPO, free_port

DASK = Path(sys.executable).with_name("dask")
DATASET = "terrain"


def ccsm(*args: str) -> subprocess.CompletedProcess[str]:
    """``ccsm`` in a subprocess, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *args],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO), "CCSM_SERVE_SAMPLE": "false"},
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def dem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rough terrain: about 300 contours (5 build chunks) and a DEM read in 16 windows of 20 cells."""
    z = fractal_heights(11, 3.0, n=64, relief_m=200.0).astype(np.float32)
    path = tmp_path_factory.mktemp("dem") / "terrain.tif"
    return write_geotiff(path, z, west=740_000.0, north=4_060_000.0, cell=30.0, crs="EPSG:32616")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``dask scheduler`` and two single-threaded ``dask worker`` processes on loopback; yields the address."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = tmp_path_factory.mktemp("dask")
    env = {**os.environ, "PYTHONPATH": str(REPO)}  # the workers import the engine from this checkout
    commands = [
        [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        *[
            [str(DASK), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
             "--name", f"w{k}", "--host", "127.0.0.1"]
            for k in range(2)
        ],
    ]
    procs = []
    try:
        for k, command in enumerate(commands):
            log = open(logs / f"{k}.log", "wb")  # noqa: SIM115 - closed with the process below
            procs.append((subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT), log))
            if k == 0:
                time.sleep(2.0)  # the scheduler listens before the workers dial it
        wait_for_workers(address, 2)
        yield address
    finally:
        for proc, log in reversed(procs):
            stop_process(proc)
            log.close()


def wait_for_workers(address: str, n: int) -> None:
    from distributed import Client

    with Client(address, timeout=30) as client:
        client.wait_for_workers(n, timeout=60)


def tasks_run_per_worker(address: str) -> dict[str, int]:
    """Tasks each worker has executed so far, by worker name."""
    from distributed import Client

    def executed(dask_worker) -> int:  # noqa: ANN001 - Dask passes its Worker
        return int(dask_worker.state.executed_count)

    with Client(address, timeout=30) as client:
        counts = client.run(executed)
        names = {a: w["name"] for a, w in client.scheduler_info()["workers"].items()}
    return {str(names[a]): c for a, c in counts.items()}


def all_tiles(store_path: Path) -> dict[tuple[str, int, int, int], bytes]:
    """Every tile of the dataset from z9 to z15, per-zoom and morph tiles, as bytes."""
    renderer = Renderer(CCSStore(store_path, readonly=True))
    info = renderer.store.dataset(DATASET)
    out: dict[tuple[str, int, int, int], bytes] = {}
    for z in range(9, 16):
        for _, x, y in tiles_covering(Bounds(*info.bounds_3857), z):
            out[("zoom", z, x, y)] = renderer.tile(DATASET, z, x, y).data or b""
            out[("morph", z, x, y)] = renderer.morph_tile(DATASET, z, x, y).data or b""
    return out


@pytest.mark.slow
def test_two_dask_workers_build_the_tiles_of_a_local_build(tmp_path: Path, dem: Path, cluster: str) -> None:
    common = [str(dem), "--id", DATASET, "--interval", "10", "--block", "20"]
    local = ccsm("build", *common, "--store", str(tmp_path / "local.sqlite"), "--workers", "2")
    assert local.returncode == 0, local.stderr
    before = tasks_run_per_worker(cluster)
    remote = ccsm("build", *common, "--store", str(tmp_path / "dask.sqlite"), "--scheduler", cluster)
    assert remote.returncode == 0, remote.stderr
    ran = {name: n - before.get(name, 0) for name, n in tasks_run_per_worker(cluster).items()}
    # 16 windows and one task per 64 contours went to the cluster, and both workers took a share.
    assert sorted(ran) == ["w0", "w1"] and min(ran.values()) > 0 and sum(ran.values()) >= 16 + 4, ran
    local_info = CCSStore(tmp_path / "local.sqlite", readonly=True).dataset(DATASET)
    dask_info = CCSStore(tmp_path / "dask.sqlite", readonly=True).dataset(DATASET)
    assert (dask_info.n_contours, dask_info.n_vertices) == (local_info.n_contours, local_info.n_vertices)
    assert local_info.n_contours > 250
    local_tiles, dask_tiles = all_tiles(tmp_path / "local.sqlite"), all_tiles(tmp_path / "dask.sqlite")
    assert sum(1 for data in local_tiles.values() if data) > 20
    assert dask_tiles.keys() == local_tiles.keys()
    differing = [key for key in local_tiles if local_tiles[key] != dask_tiles[key]]
    assert not differing, f"{len(differing)} tiles differ, e.g. {differing[:3]}"


def test_unreachable_scheduler_is_a_clear_error(tmp_path: Path, dem: Path) -> None:
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    result = ccsm(
        "build", str(dem), "--interval", "10", "--store", str(tmp_path / "s.sqlite"), "--scheduler", address
    )
    assert result.returncode == 2
    assert f"scheduler {address}: cannot connect" in result.stderr
    assert not (tmp_path / "s.sqlite").exists() or DATASET not in CCSStore(tmp_path / "s.sqlite").dataset_ids()
