"""One Dask worker against two (issue 12 item 6, issue 26 item 3): the same ``ccsm build --scheduler`` of one
DEM, timed, with a real ``dask scheduler`` and N single-threaded ``dask worker`` processes on loopback, then the
stores' tiles compared byte for byte; for each data size (the 4x and 16x terrain of bench_scale.py by default).

The goal is two workers at least 1.8x as fast as one on a 2-core machine: everything but the client's own share
(reading the source, fitting the scale model, writing the store) runs on the workers. The CPU seconds of the
client (the ``ccsm build`` process and its children, from ``getrusage``), of the scheduler and of the workers
(each worker's nanny and worker process, from psutil) during each build are printed with it: with one worker
the client's work runs on the other core for free, with two it takes a core from them. From them:

- client %: the client's share of all the CPU, client / (client + scheduler + workers); by Amdahl's law no
  cluster makes the build more than 1 / share times faster (goal <= 3 %, a bound of >= 30x);
- idle %: the workers' idle share, 1 - workers' CPU / (workers x build wall time);
- speed-up: each build's wall time against the first worker count's (1 -> 2 workers: goal >= 1.8x), and a
  summary line per data size with the 1 -> 2 speed-up and the shares with the most workers.

Usage: python bench/bench_dask.py [--sizes 4,16 | --dem PATH] [--interval 20] [--workers 1,2] [--repeat 1]
       [--code DIR ...]
(--sizes: bench_scale.py's terrains, N times its 1x terrain's vertices, written into var/bench-scale if missing;
--code: the checkouts whose code runs the builds, e.g. ``--code /work/main --code .`` to compare two in one run)
"""

from __future__ import annotations

import argparse
import hashlib
import os
import resource
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

from support.processes import stop_process  # noqa: E402

DASK = Path(sys.executable).with_name("dask")


def code_env(code: Path) -> dict[str, str]:
    """The environment that makes the client, the scheduler and the workers run the checkout at ``code``."""
    return {**os.environ, "PYTHONPATH": str(code), "CCSM_SERVE_SAMPLE": "false"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_cluster(workers: int, logs: Path, env: dict[str, str]) -> tuple[str, list[subprocess.Popen[bytes]]]:
    """A scheduler and ``workers`` single-threaded workers on loopback; the address and the processes."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
    procs = [subprocess.Popen(scheduler, env=env, stdout=open(logs / "scheduler.log", "wb"), stderr=subprocess.STDOUT)]  # noqa: SIM115
    time.sleep(2.0)
    for k in range(workers):
        worker = [
            str(DASK),
            "worker",
            address,
            "--nworkers",
            "1",
            "--nthreads",
            "1",
            "--no-dashboard",
            "--name",
            f"w{k}",
            "--host",
            "127.0.0.1",
        ]
        procs.append(subprocess.Popen(worker, env=env, stdout=open(logs / f"w{k}.log", "wb"), stderr=subprocess.STDOUT))  # noqa: SIM115
    with Client(address, timeout=30) as client:
        client.wait_for_workers(workers, timeout=60)
    return address, procs


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for proc in reversed(procs):
        stop_process(proc)


def cpu_seconds(proc: subprocess.Popen[bytes]) -> float:
    """CPU seconds (user + system) used so far by ``proc`` and its children (a worker's nanny runs the worker)."""
    import psutil

    total = 0.0
    parent = psutil.Process(proc.pid)
    for p in [parent, *parent.children(recursive=True)]:
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system
    return total


def client_cpu() -> float:
    """CPU seconds of this process's finished children: the ``ccsm build`` clients run so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def build(
    dem: Path, interval: float, store: Path, scheduler: str, procs: list[subprocess.Popen[bytes]], env: dict[str, str]
) -> tuple[float, float, float, float]:
    """Wall time of ``ccsm build`` on the cluster, as a user runs it, and the CPU seconds it took in the
    client, the scheduler and the workers: where the client's share is large, two workers cannot be twice
    as fast as one (the client's serial work runs beside one worker on the other core, but not beside two)."""
    command = [
        sys.executable,
        "-c",
        "from app.cli import main; main()",
        "build",
        str(dem),
        "--interval",
        str(interval),
        "--store",
        str(store),
        "--id",
        "bench",
        "--force",
        "--scheduler",
        scheduler,
    ]
    before = [cpu_seconds(p) for p in procs]
    client0 = client_cpu()
    t0 = time.perf_counter()
    subprocess.run(command, cwd=env["PYTHONPATH"], env=env, check=True, capture_output=True)
    seconds = time.perf_counter() - t0
    used = [cpu_seconds(p) - b for p, b in zip(procs, before, strict=True)]
    return seconds, client_cpu() - client0, used[0], sum(used[1:])


def tiles_digest(store_path: Path) -> str:
    """SHA-256 over every z12 tile of the dataset and a z14 sample: equal digests, equal tiles."""
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    # Opened for writing: a store an older checkout wrote (--code) is migrated to this format first.
    store = CCSStore(store_path)
    bounds = Bounds(*store.dataset("bench").bounds_3857)
    renderer = Renderer(store)
    digest = hashlib.sha256()
    for z, step in ((12, 1), (14, 7)):
        for tz, tx, ty in tiles_covering(bounds, z)[::step]:
            digest.update(renderer.tile("bench", tz, tx, ty).data or b"")
    store.close()
    return digest.hexdigest()[:16]


def dems(args: argparse.Namespace) -> list[tuple[str, Path]]:
    """(label, DEM) of every data size to run: ``--dem``, else the bench_scale.py terrain of each of ``--sizes``
    (written into var/bench-scale if missing)."""
    if args.dem is not None:
        return [(args.dem.name, args.dem.resolve())]
    import numpy as np
    from bench_scale import BASE_SIDE, WORK, terrain, write_dem

    WORK.mkdir(parents=True, exist_ok=True)
    out = []
    for size in [int(s) for s in args.sizes.split(",")]:
        side = int(BASE_SIDE * np.sqrt(size))
        dem = WORK / f"terrain-{side}.tif"
        if not dem.exists():
            write_dem(dem, terrain(side))
        out.append((f"terrain {size}x", dem.resolve()))
    return out


def shares(seconds: float, workers: int, client: float, sched: float, work: float) -> tuple[float, float]:
    """The client's share of all the CPU of a build (client / (client + scheduler + workers)) and the workers'
    idle share (1 - worker CPU / (workers x wall time))."""
    return client / (client + sched + work), 1.0 - work / (workers * seconds)


def summary(label: str, rows: dict[int, tuple[float, float, float, float]]) -> None:
    """One line per data size: the 1 -> 2 worker speed-up, and the client's share and the workers' idle share
    with the most workers run; the client's share bounds any cluster's speed-up at 1 / share (Amdahl)."""
    n = max(rows)
    client_share, idle = shares(rows[n][0], n, *rows[n][1:])
    speedup = f"{rows[1][0] / rows[2][0]:.2f}x" if 1 in rows and 2 in rows else "n/a (run --workers 1,2)"
    print(
        f"  {label}: speed-up 1 -> 2 workers {speedup} (goal >= 1.8x); with {n} worker(s): client share of all "
        f"CPU {client_share:.1%} (goal <= 3 %; Amdahl bound {1 / client_share:.1f}x), workers idle {idle:.1%}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--dem", type=Path, default=None, help="one DEM to build instead of --sizes")
    parser.add_argument(
        "--sizes", default="4,16", help="bench_scale.py terrains to build, multiples of its 1x terrain's vertices"
    )
    parser.add_argument("--interval", type=float, default=20.0)
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument(
        "--code",
        type=Path,
        action="append",
        default=None,
        help="checkout whose code runs the build (repeatable, to compare two in one run) [this one]",
    )
    args = parser.parse_args()
    print(f"interval {args.interval:g} m; {os.cpu_count()} cores; best of {args.repeat}")
    print(
        "CPU s: of the ccsm build client, the scheduler and all workers together, during the build; client %: the "
        "client's share of all that CPU; idle %: 1 - worker CPU / (workers x build s)"
    )
    header = (
        f"{'data':>12} {'code':>24} {'workers':>7} {'build s':>8} {'speed-up':>8} {'client':>7} {'sched':>6}"
        f" {'workers':>8} {'client %':>8} {'idle %':>7} {'tiles sha256':>16}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for label, dem in dems(args):
            print(f"\nDEM {dem.name} ({label})")
            print(header)
            for code in [c.resolve() for c in args.code or [REPO]]:
                env = code_env(code)
                rows: dict[int, tuple[float, float, float, float]] = {}
                for n in [int(w) for w in args.workers.split(",")]:
                    logs = Path(tmp) / f"logs-{dem.stem}-{code.name}-{n}"
                    logs.mkdir()
                    address, procs = start_cluster(n, logs, env)
                    try:
                        store = Path(tmp) / f"{dem.stem}-{code.name}-w{n}.sqlite"
                        rows[n] = min(build(dem, args.interval, store, address, procs, env) for _ in range(args.repeat))
                    finally:
                        stop(procs)
                    seconds, client, sched, work = rows[n]
                    first = next(iter(rows.values()))[0]
                    client_share, idle = shares(seconds, n, client, sched, work)
                    print(
                        f"{label:>12} {str(code)[-24:]:>24} {n:7d} {seconds:8.1f} {first / seconds:7.2f}x "
                        f"{client:7.1f} {sched:6.1f} {work:8.1f} {client_share:8.1%} {idle:7.1%} "
                        f"{tiles_digest(store):>16}",
                        flush=True,
                    )
                summary(f"{label}, {code.name}", rows)


if __name__ == "__main__":
    main()
