"""One Dask worker against two (issue 12 item 6): the same ``ccsm build --scheduler`` of one DEM, timed, with a
real ``dask scheduler`` and N single-threaded ``dask worker`` processes on loopback, then the stores' tiles
compared byte for byte.

The goal is two workers at least 1.8x as fast as one on a 2-core machine: everything but the client's own share
(joining the windows' lines, fitting the scale model, writing the store) runs on the workers.

Usage: python bench/bench_dask.py [--dem PATH --interval 20] [--workers 1,2] [--repeat 1]
(default DEM: the 4x terrain of bench_scale.py, written into var/bench-scale if missing)
"""

from __future__ import annotations

import argparse
import hashlib
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "bench"))

DASK = Path(sys.executable).with_name("dask")
ENV = {**os.environ, "PYTHONPATH": str(REPO), "CCSM_SERVE_SAMPLE": "false"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_cluster(workers: int, logs: Path) -> tuple[str, list[subprocess.Popen[bytes]]]:
    """A scheduler and ``workers`` single-threaded workers on loopback; the address and the processes."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
    procs = [subprocess.Popen(scheduler, env=ENV, stdout=open(logs / "scheduler.log", "wb"), stderr=subprocess.STDOUT)]  # noqa: SIM115
    time.sleep(2.0)
    for k in range(workers):
        worker = [str(DASK), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                  "--name", f"w{k}", "--host", "127.0.0.1"]
        procs.append(subprocess.Popen(worker, env=ENV, stdout=open(logs / f"w{k}.log", "wb"), stderr=subprocess.STDOUT))  # noqa: SIM115
    with Client(address, timeout=30) as client:
        client.wait_for_workers(workers, timeout=60)
    return address, procs


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for proc in reversed(procs):
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def build(dem: Path, interval: float, store: Path, scheduler: str) -> float:
    """Wall time of ``ccsm build`` on the cluster, as a user runs it."""
    command = [sys.executable, "-c", "from app.cli import main; main()", "build", str(dem), "--interval",
               str(interval), "--store", str(store), "--id", "bench", "--force", "--scheduler", scheduler]
    t0 = time.perf_counter()
    subprocess.run(command, cwd=REPO, env=ENV, check=True, capture_output=True)
    return time.perf_counter() - t0


def tiles_digest(store_path: Path) -> str:
    """SHA-256 over every z12 tile of the dataset and a z14 sample: equal digests, equal tiles."""
    from engine.serve.renderer import Renderer
    from engine.store.sqlite import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    store = CCSStore(store_path, readonly=True)
    bounds = Bounds(*store.dataset("bench").bounds_3857)
    renderer = Renderer(store)
    digest = hashlib.sha256()
    for z, step in ((12, 1), (14, 7)):
        for tz, tx, ty in tiles_covering(bounds, z)[::step]:
            digest.update(renderer.tile("bench", tz, tx, ty).data or b"")
    store.close()
    return digest.hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--dem", type=Path, default=None)
    parser.add_argument("--interval", type=float, default=20.0)
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    dem = args.dem
    if dem is None:
        from bench_scale import BASE_SIDE, WORK, terrain, write_dem

        WORK.mkdir(parents=True, exist_ok=True)
        dem = WORK / f"terrain-{BASE_SIDE * 2}.tif"
        if not dem.exists():
            write_dem(dem, terrain(BASE_SIDE * 2))
    print(f"DEM {dem.name}, interval {args.interval:g} m; {os.cpu_count()} cores; best of {args.repeat}")
    print(f"{'workers':>7} {'build s':>8} {'speed-up':>8} {'tiles sha256':>16}")
    first = None
    with tempfile.TemporaryDirectory() as tmp:
        for n in [int(w) for w in args.workers.split(",")]:
            logs = Path(tmp) / f"logs{n}"
            logs.mkdir()
            address, procs = start_cluster(n, logs)
            try:
                store = Path(tmp) / f"w{n}.sqlite"
                seconds = min(build(dem, args.interval, store, address) for _ in range(args.repeat))
            finally:
                stop(procs)
            first = first or seconds
            print(f"{n:7d} {seconds:8.1f} {first / seconds:7.2f}x {tiles_digest(store):>16}", flush=True)


if __name__ == "__main__":
    main()
