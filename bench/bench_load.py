"""Mixed-load benchmark of the service (issue 10, item 5): does any request stall another?

Starts ``ccsm serve`` (real uvicorn on loopback) on the bundled sample, then runs two phases of the same
length:

1. **alone**: clients asking plain ccsm z12 tiles (no ETag, every request renders);
2. **mix**: the same clients, plus hostile ones: every method at fractional zooms (wm, dp, vw, original),
   ``/simplify`` at varied scales and methods, morph tiles; optionally uploads and deletes (``--token``,
   once writes need one).

Prints per route: requests, throughput, p50/p95/p99 and status counts; the p99 of the plain ccsm z12 tiles
alone vs under the mix (goal: within 2x); and the largest ``/healthz`` latency seen during the mix, polled
every 50 ms (goal: under 50 ms). To tell why a tail is long, it also prints where the plain tiles' time
went (from their ``Server-Timing`` header: waiting for a render worker, drawing, and the rest, i.e. the
event loop, the network and the clients), over all of them and over the slowest 1 %, and the CPU each part
of the server (event loop, render workers by niceness, checks and builds) and the clients used per phase.

The load clients run on the same two cores as the server. ``--client-niceness 5`` runs their threads at the
render workers' niceness, as if the clients were on other machines (as in a deployment): then the server's
event loop is not competing with its own load generator for a core. The /healthz probe runs at niceness 0.

``--connections N`` (issue 28) runs another test instead: /healthz polled alone (the idle figure), then
while N connections at once ask z12 tiles and ``/datasets`` (``bench/many_connections.py``, a process of its
own at ``--client-niceness``); it prints their statuses and latencies, /healthz p50/p99/max in both, and the
ratio (goal: max within 50 ms).

Usage: python bench/bench_load.py [--seconds 30] [--clients 4] [--hostile 4] [--workers 1] [--token T]
       [--client-niceness N] [--connections N]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import random
import subprocess
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
WORK = REPO / "var" / "bench"
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # tests/app/helpers imports support.* as pytest does

from tests.app.conftest import LiveServer  # noqa: E402
from tests.app.helpers import tile_for  # noqa: E402


@dataclass
class Record:
    """Latencies (seconds) and status codes per route label."""

    lat: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    status: dict[str, dict[int, int]] = field(default_factory=lambda: defaultdict(lambda: defaultdict(int)))
    #: Per route label, (total, queue, render) seconds of each drawn tile, from its Server-Timing header.
    timing: dict[str, list[tuple[float, float, float]]] = field(default_factory=lambda: defaultdict(list))
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, label: str, seconds: float, status: int, server_timing: str | None = None) -> None:
        with self.lock:
            self.lat[label].append(seconds)
            self.status[label][status] += 1
            if server_timing:
                queue, render = parse_server_timing(server_timing)
                self.timing[label].append((seconds, queue, render))


def parse_server_timing(header: str) -> tuple[float, float]:
    """(queue, render) seconds from ``Server-Timing: queue;dur=MS, render;dur=MS`` (app/routes/tiles.py)."""
    durations = {}
    for metric in header.split(","):
        name, _, dur = metric.strip().partition(";dur=")
        durations[name] = float(dur) / 1000
    return durations.get("queue", 0.0), durations.get("render", 0.0)


def sample_store() -> Path:
    """The sample built once into var/bench/load-sample.sqlite (``ccsm build``)."""
    store = WORK / "load-sample.sqlite"
    if not store.exists():
        WORK.mkdir(parents=True, exist_ok=True)
        print("building the sample store (once)...", flush=True)
        subprocess.run(
            [sys.executable, "-c", "from app.cli import main; main()", "build", "--store", str(store)],
            cwd=REPO,
            check=True,
        )
    return store


def start(store: Path, workers: int, token: str | None) -> LiveServer:
    env = {"CCSM_STORE_PATH": str(store)}
    if token:
        env["CCSM_ADMIN_TOKEN"] = token
    server = LiveServer(env, args=["--workers", str(workers)], log=WORK / "bench-load-server.log")
    server.wait_healthy(600)  # the first start compiles the numba kernels (minutes on a busy machine)
    server.wait_ready("sample")
    return server


def z12_tiles(base: str) -> list[tuple[int, int, int]]:
    """The z12 tiles over the sample's extent that hold contours."""
    west, south, east, north = httpx.get(f"{base}/datasets/sample").json()["bounds"]
    z0, x0, y0 = tile_for(west, north, 12)
    _, x1, y1 = tile_for(east, south, 12)
    tiles = [(12, x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]
    return [t for t in tiles if httpx.get("{}/tiles/sample/{}/{}/{}.mvt".format(base, *t)).status_code == 200]


def loop(stop: threading.Event, client: httpx.Client, rec: Record, pick: Callable[[], tuple[str, str]]) -> None:
    """Ask ``pick()`` (label, path) requests one after another until ``stop``."""
    while not stop.is_set():
        label, path = pick()
        t0 = time.perf_counter()
        timing = None
        try:
            r = client.get(path)
            status, timing = r.status_code, r.headers.get("server-timing")
        except httpx.HTTPError:
            status = 0
        rec.add(label, time.perf_counter() - t0, status, timing)


def hostile_picker(base: str, center: tuple[float, float], rng: random.Random) -> Callable[[], tuple[str, str]]:
    """Random expensive requests: baselines at fractional zooms, /simplify, morph tiles, original."""
    lon, lat = center

    def pick() -> tuple[str, str]:
        kind = rng.choice(["wm", "dp", "vw", "original", "simplify", "morph", "ccsm-frac"])
        z = rng.randint(8, 14)
        _, x, y = tile_for(lon + rng.uniform(-0.08, 0.08), lat + rng.uniform(-0.06, 0.06), z)
        frac = round(z + rng.random() * 0.99, 3)
        if kind == "simplify":
            scale = rng.choice([100_000, 250_000, 500_000, 1_000_000]) * rng.uniform(0.9, 1.1)
            method = rng.choice(["ccsm", "dp", "vw", "wm"])
            return f"simplify {method}", f"{base}/simplify?scale={scale:.0f}&method={method}"
        if kind == "morph":
            return "morph tile", f"{base}/morph/sample/{z}/{x}/{y}.mvt"
        if kind == "ccsm-frac":
            return "ccsm tile, fractional zoom", f"{base}/tiles/sample/{z}/{x}/{y}.mvt?zoom={frac}"
        return f"{kind} tile", f"{base}/tiles/sample/{z}/{x}/{y}.mvt?method={kind}&zoom={frac}"

    return pick


def writer_loop(stop: threading.Event, base: str, token: str, rec: Record) -> None:
    """Upload a small dataset, wait for it, delete it; again until ``stop`` (only with --token)."""
    from tests.app.conftest import synthetic_features

    body = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=5)[:6]})
    headers = {"authorization": f"Bearer {token}", "content-type": "application/geo+json"}
    n = 0
    with httpx.Client(timeout=60) as client:
        while not stop.is_set():
            n += 1
            t0 = time.perf_counter()
            r = client.post(f"{base}/datasets?id=bench-up-{n}", content=body, headers=headers)
            rec.add("POST /datasets", time.perf_counter() - t0, r.status_code)
            ready_by = time.monotonic() + 60
            while not stop.is_set() and time.monotonic() < ready_by:
                if client.get(f"{base}/datasets/bench-up-{n}").json().get("state") != "building":
                    break
                time.sleep(0.2)
            t0 = time.perf_counter()
            r = client.delete(f"{base}/datasets/bench-up-{n}", headers=headers)
            rec.add("DELETE /datasets", time.perf_counter() - t0, r.status_code)


def health_probe(base: str, seconds: float, conn: Connection) -> None:
    """Poll /healthz every 50 ms for ``seconds``; send the latencies back. It runs in a process of its own,
    so the load clients' threads (and their GIL) do not add to what it measures."""
    out: list[float] = []
    end = time.monotonic() + seconds
    with httpx.Client(timeout=30) as client:
        while time.monotonic() < end:
            t0 = time.perf_counter()
            client.get(f"{base}/healthz")
            out.append(time.perf_counter() - t0)
            time.sleep(0.05)
    conn.send(out)


def _niced(run: Callable[[], None], niceness: int) -> Callable[[], None]:
    def niced_run() -> None:
        if niceness:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), niceness)
        run()

    return niced_run


def run_phase(
    base: str, tiles: list[tuple[int, int, int]], args: argparse.Namespace, mix: bool
) -> tuple[Record, list[float], float]:
    """Run the plain clients (and with ``mix`` the hostile ones and the /healthz probe) for --seconds."""
    rec = Record()
    stop = threading.Event()
    health: list[float] = []
    threads = []
    info = httpx.get(f"{base}/datasets/sample").json()
    center = (info["center"][0], info["center"][1])
    for i in range(args.clients):
        rng = random.Random(i)
        client = httpx.Client(timeout=120)

        def plain(rng: random.Random = rng) -> tuple[str, str]:
            return "ccsm z12 tile", "{}/tiles/sample/{}/{}/{}.mvt".format(base, *rng.choice(tiles))

        threads.append(threading.Thread(target=loop, args=(stop, client, rec, plain)))
    if mix:
        for i in range(args.hostile):
            client = httpx.Client(timeout=120)
            pick = hostile_picker(base, center, random.Random(100 + i))
            threads.append(threading.Thread(target=loop, args=(stop, client, rec, pick)))
        if args.token:
            threads.append(threading.Thread(target=writer_loop, args=(stop, base, args.token, rec)))
    for t in threads:  # Linux: a thread's niceness is its own, so the probe process below stays at 0
        t.run = _niced(t.run, args.client_niceness)  # type: ignore[method-assign]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    if mix:
        mine, theirs = multiprocessing.Pipe()
        probe = multiprocessing.get_context("spawn").Process(target=health_probe, args=(base, args.seconds, theirs))
        probe.start()
    time.sleep(args.seconds)
    if mix:
        health = mine.recv()
        probe.join()
    stop.set()
    for t in threads:
        t.join()
    return rec, health, time.perf_counter() - t0


def cpu_by_role(server_pid: int) -> dict[str, float]:
    """CPU seconds used so far by the server's event loop, its render workers by niceness (light and morph
    lanes +5, heavy lane +10), its other processes (upload checks, builds; with those that ended), and this
    load generator (the clients' threads)."""
    import psutil

    server = psutil.Process(server_pid)
    own = server.nice()
    roles: dict[str, float] = defaultdict(float)
    times = server.cpu_times()
    roles["server (event loop)"] += times.user + times.system
    roles["ended processes (checks, builds, replaced workers)"] += times.children_user + times.children_system
    for child in server.children(recursive=True):
        try:
            t = child.cpu_times()
            added = child.nice() - own
            if child.parent().pid == server_pid and "forkserver" in " ".join(child.cmdline()):
                roles["ended processes (checks, builds, replaced workers)"] += t.children_user + t.children_system
                role = "fork server"
            elif added == 5 and child.parent().pid != server_pid:
                role = "render workers +5 (light, morph)"
            elif added == 10 and child.parent().pid != server_pid:
                role = "heavy workers and checks +10"
            else:
                role = "builds and others"
            roles[role] += t.user + t.system
        except psutil.Error:
            continue
    me = psutil.Process().cpu_times()
    roles["load clients (this process)"] += me.user + me.system
    return roles


def report_cpu(before: dict[str, float], after: dict[str, float], seconds: float) -> None:
    print(
        "  CPU, cores used on average: "
        + ", ".join(f"{role} {(after[role] - before.get(role, 0.0)) / seconds:.2f}" for role in sorted(after))
    )


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.array(values) * 1000, q)) if values else float("nan")


def report(title: str, rec: Record, seconds: float) -> None:
    print(f"\n{title} ({seconds:.0f} s)")
    print(f"  {'route':30s} {'n':>6s} {'req/s':>7s} {'p50 ms':>8s} {'p95 ms':>8s} {'p99 ms':>8s}  statuses")
    for label in sorted(rec.lat):
        lat = rec.lat[label]
        codes = " ".join(f"{k}:{v}" for k, v in sorted(rec.status[label].items()))
        print(
            f"  {label:30s} {len(lat):6d} {len(lat) / seconds:7.1f} {pct(lat, 50):8.1f} {pct(lat, 95):8.1f} "
            f"{pct(lat, 99):8.1f}  {codes}"
        )


def breakdown(title: str, rec: Record, label: str) -> None:
    """Where the time of ``label`` requests went: waiting for a render worker (queue), drawing (render), and
    the rest (the event loop, the network, the client's own threads); over all of them and over the slowest
    1 % (the tail the p99 measures)."""
    rows = np.array(rec.timing.get(label, []), dtype=float).reshape(-1, 3) * 1000
    if len(rows) == 0:
        return
    rest = rows[:, 0] - rows[:, 1] - rows[:, 2]
    tail = rows[:, 0] >= np.percentile(rows[:, 0], 99)
    print(
        f"  {title}, {label} ({len(rows)} drawn): "
        f"queue p50 {np.percentile(rows[:, 1], 50):.1f} / p99 {np.percentile(rows[:, 1], 99):.1f} ms, "
        f"render p50 {np.percentile(rows[:, 2], 50):.1f} / p99 {np.percentile(rows[:, 2], 99):.1f} ms, "
        f"rest p50 {np.percentile(rest, 50):.1f} / p99 {np.percentile(rest, 99):.1f} ms; "
        f"slowest 1 % ({tail.sum()}): mean total {rows[tail, 0].mean():.1f} = queue {rows[tail, 1].mean():.1f}"
        f" + render {rows[tail, 2].mean():.1f} + rest {rest[tail].mean():.1f} ms"
    )


def run_connections(base: str, port: int, tiles: list[tuple[int, int, int]], args: argparse.Namespace) -> None:
    """/healthz alone, then during ``--connections`` open connections (see the module docstring)."""
    from bench.many_connections import run_client, summarize

    spawn = multiprocessing.get_context("spawn")

    def probe(seconds: float) -> tuple[Connection, multiprocessing.process.BaseProcess]:
        mine, theirs = multiprocessing.Pipe()
        proc = spawn.Process(target=health_probe, args=(base, seconds, theirs))
        proc.start()
        return mine, proc

    idle_pipe, idle_proc = probe(min(args.seconds, 10.0))
    idle = idle_pipe.recv()
    idle_proc.join()
    cpu0 = cpu_by_role(int(args.server_pid))
    load_pipe, theirs = multiprocessing.Pipe()
    client = spawn.Process(
        target=run_client,
        args=("127.0.0.1", port, tiles, args.connections, args.seconds, args.client_niceness, theirs),
    )
    client.start()
    time.sleep(1.0)  # the connections open first
    health_pipe, health_proc = probe(args.seconds - 2.0)
    health = health_pipe.recv()
    health_proc.join()
    samples, client_cpu = load_pipe.recv()
    client.join()
    cpu1 = cpu_by_role(int(args.server_pid))
    print(f"\n{args.connections} connections ({args.seconds:.0f} s, load client niceness {args.client_niceness})")
    print(f"  {'route':30s} {'n':>6s} {'req/s':>7s} {'p50 ms':>8s} {'p99 ms':>8s} {'max ms':>8s}  statuses")
    for label, (lat, codes) in sorted(summarize(samples).items()):
        text = " ".join(f"{k}:{v}" for k, v in sorted(codes.items()))
        print(
            f"  {label:30s} {len(lat):6d} {len(lat) / args.seconds:7.1f} {pct(lat, 50):8.1f} {pct(lat, 99):8.1f} "
            f"{max(lat) * 1000:8.1f}  {text}"
        )
    report_cpu(cpu0, cpu1, args.seconds)
    print(f"  load client process: {client_cpu / args.seconds:.2f} cores")
    for title, values in (("alone", idle), (f"at {args.connections} connections", health)):
        print(
            f"/healthz {title}: {len(values)} polls, p50 {pct(values, 50):.1f} ms, p99 {pct(values, 99):.1f} ms, "
            f"max {max(values) * 1000:.1f} ms"
        )
    print(
        f"/healthz loaded / alone: p50 {pct(health, 50) / pct(idle, 50):.1f}x, "
        f"max {max(health) / max(idle):.1f}x (goal: max <= 50 ms)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=30.0, help="length of each phase")
    parser.add_argument("--clients", type=int, default=4, help="clients asking plain ccsm z12 tiles")
    parser.add_argument("--hostile", type=int, default=4, help="clients asking expensive requests (mix)")
    parser.add_argument("--workers", type=int, default=1, help="uvicorn worker processes")
    parser.add_argument("--token", default=None, help="admin token: add uploads and deletes to the mix")
    parser.add_argument(
        "--client-niceness",
        type=int,
        default=0,
        help="niceness of the load clients' threads (5: as if they ran on other machines)",
    )
    parser.add_argument(
        "--connections",
        type=int,
        default=0,
        help="instead: /healthz alone, then during this many open connections (z12 tiles, /datasets)",
    )
    args = parser.parse_args()
    store = sample_store()
    server = start(store, args.workers, args.token)
    try:
        base = server.url
        tiles = z12_tiles(base)
        if args.connections:
            args.server_pid = server.proc.pid
            run_connections(base, server.port, tiles, args)
            return
        print(
            f"server {base}, {args.workers} uvicorn worker(s); {len(tiles)} z12 tiles with contours; "
            f"{args.clients} plain clients, {args.hostile} hostile clients (niceness {args.client_niceness}), "
            f"{os.cpu_count()} cores"
        )
        cpu0 = cpu_by_role(server.proc.pid)
        alone, _, s_alone = run_phase(base, tiles, args, mix=False)
        cpu1 = cpu_by_role(server.proc.pid)
        report("alone: plain ccsm z12 tiles", alone, s_alone)
        report_cpu(cpu0, cpu1, s_alone)
        mixed, health, s_mix = run_phase(base, tiles, args, mix=True)
        report("mix: plain tiles + hostile requests", mixed, s_mix)
        report_cpu(cpu1, cpu_by_role(server.proc.pid), s_mix)
        p_alone, p_mix = pct(alone.lat["ccsm z12 tile"], 99), pct(mixed.lat["ccsm z12 tile"], 99)
        print(
            f"\nccsm z12 p99: alone {p_alone:.1f} ms, under the mix {p_mix:.1f} ms ({p_mix / p_alone:.2f}x; goal <= 2x)"
        )
        print("where the plain tiles' time went (Server-Timing):")
        breakdown("alone", alone, "ccsm z12 tile")
        breakdown("mix", mixed, "ccsm z12 tile")
        breakdown("mix", mixed, "morph tile")
        print(
            f"/healthz during the mix: {len(health)} polls, max {max(health) * 1000:.1f} ms, "
            f"p99 {pct(health, 99):.1f} ms (goal < 50 ms)"
        )
    finally:
        server.stop()


if __name__ == "__main__":
    main()
