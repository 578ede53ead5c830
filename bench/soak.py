"""Soak test (issue 10, item 5): a steady mixed load for minutes; prints errors and memory over time.

Starts ``ccsm serve --workers N`` (default 2) on the bundled sample and runs clients asking tiles of every
method at fractional zooms, morph tiles and ``/simplify``. Every ``--every`` seconds it prints the requests
so far, the errors (5xx other than a deadline/busy 503, and transport failures), the 503s, and the memory
of the server and of all its processes (uvicorn workers, render workers): RSS, and PSS, which counts the
pages the forked render workers share once. Goal: 0 errors, memory flat after warm-up.

Usage: python bench/soak.py [--minutes 10] [--workers 2] [--clients 4] [--every 30]
"""

from __future__ import annotations

import argparse
import random
import sys
import threading
import time
from pathlib import Path

import httpx
import psutil

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench.bench_load import hostile_picker, sample_store, start  # noqa: E402


class Counts:
    """Requests, errors and 503s so far (thread-safe)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.requests = self.errors = self.busy = 0
        self.examples: list[str] = []

    def add(self, status: int, path: str) -> None:
        with self.lock:
            self.requests += 1
            if status == 503:
                self.busy += 1
            elif status == 0 or status >= 500:
                self.errors += 1
                if len(self.examples) < 5:
                    self.examples.append(f"{status} {path}")


def client_loop(stop: threading.Event, base: str, center: tuple[float, float], seed: int, counts: Counts) -> None:
    pick = hostile_picker(base, center, random.Random(seed))
    with httpx.Client(timeout=120) as client:
        while not stop.is_set():
            _, path = pick()
            try:
                status = client.get(path).status_code
            except httpx.HTTPError:
                status = 0
            counts.add(status, path)


def memory_mb(pid: int) -> tuple[float, float, float]:
    """(RSS of the server process, RSS summed over it and all its descendants, PSS summed likewise), MB.

    The render workers are forked from one fork server and share its pages (the engine, numba's code), so
    summed RSS counts those pages once per worker; PSS shares them out and adds up to the real total.
    """
    root = psutil.Process(pid)
    rss = pss = 0
    for p in [root, *root.children(recursive=True)]:
        try:
            info = p.memory_full_info()
        except psutil.NoSuchProcess:
            continue
        rss += info.rss
        pss += getattr(info, "pss", info.rss)
    return root.memory_info().rss / 2**20, rss / 2**20, pss / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=10.0, help="length of the soak")
    parser.add_argument("--workers", type=int, default=2, help="uvicorn worker processes")
    parser.add_argument("--clients", type=int, default=4, help="concurrent clients")
    parser.add_argument("--every", type=float, default=30.0, help="seconds between reports")
    args = parser.parse_args()
    server = start(sample_store(), args.workers, None)
    counts = Counts()
    stop = threading.Event()
    try:
        info = httpx.get(f"{server.url}/datasets/sample").json()
        center = (info["center"][0], info["center"][1])
        threads = [
            threading.Thread(target=client_loop, args=(stop, server.url, center, seed, counts))
            for seed in range(args.clients)
        ]
        for t in threads:
            t.start()
        t0 = time.monotonic()
        print(f"soak: {args.minutes:g} min, {args.workers} uvicorn workers, {args.clients} clients, {server.url}")
        print(
            f"{'t (s)':>6s} {'requests':>9s} {'errors':>7s} {'503':>5s} {'server RSS MB':>14s} "
            f"{'all RSS MB':>11s} {'all PSS MB':>11s}"
        )
        end = t0 + args.minutes * 60
        while time.monotonic() < end:
            time.sleep(min(args.every, max(end - time.monotonic(), 0)))
            own, rss, pss = memory_mb(server.proc.pid)
            print(
                f"{time.monotonic() - t0:6.0f} {counts.requests:9d} {counts.errors:7d} {counts.busy:5d} "
                f"{own:14.0f} {rss:11.0f} {pss:11.0f}",
                flush=True,
            )
        stop.set()
        for t in threads:
            t.join()
        print(f"errors: {counts.errors}" + (f" (e.g. {counts.examples})" if counts.examples else ""))
    finally:
        stop.set()
        server.stop()


if __name__ == "__main__":
    main()
