"""Many open connections at once (issue 28, item 3), the load client of ``bench_load.py --connections N``.

N asyncio connections in one process, each asking, one after another and kept alive, plain ccsm z12 tiles
(4 in 5) and ``/datasets`` (1 in 5). A connection the server closes (a refusal over the per-client cap, a
timeout) is opened again at once, as a hostile client would. A small HTTP/1.1 client over asyncio streams,
not httpx, so the load generator spends its CPU on requests, not on its own machinery.
"""

from __future__ import annotations

import asyncio
import os
import random
import time
from collections import defaultdict
from multiprocessing.connection import Connection

#: (label, seconds, status) of one request; status 0: the connection failed or closed without an answer.
Sample = tuple[str, float, int]


async def _read_response(reader: asyncio.StreamReader) -> tuple[int, bool]:
    """(status, server keeps the connection) of one response, its body read and dropped."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:] if ln)}
    if headers.get("transfer-encoding", "").lower() == "chunked":
        while True:
            size = int((await reader.readuntil(b"\r\n")).strip().split(b";")[0], 16)
            await reader.readexactly(size + 2)
            if size == 0:
                break
    else:
        await reader.readexactly(int(headers.get("content-length", "0")))
    return status, headers.get("connection", "").lower() != "close"


async def _connection(
    host: str, port: int, tiles: list[tuple[int, int, int]], end: float, rng: random.Random, out: list[Sample]
) -> None:
    """One client connection asking until ``end``; reopened whenever the server closes it."""
    while time.monotonic() < end:
        try:
            reader, writer = await asyncio.open_connection(host, port)
        except OSError:
            out.append(("connect", 0.0, 0))
            await asyncio.sleep(0.05)
            continue
        try:
            while time.monotonic() < end:
                if rng.random() < 0.8:
                    label, path = "ccsm z12 tile", "/tiles/sample/{}/{}/{}.mvt".format(*rng.choice(tiles))
                else:
                    label, path = "GET /datasets", "/datasets"
                t0 = time.perf_counter()
                writer.write(f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
                try:
                    status, keep = await _read_response(reader)
                except (asyncio.IncompleteReadError, ConnectionError, ValueError):
                    out.append((label, time.perf_counter() - t0, 0))
                    break
                out.append((label, time.perf_counter() - t0, status))
                if not keep:
                    break
        finally:
            writer.close()


async def _run(
    host: str, port: int, tiles: list[tuple[int, int, int]], connections: int, seconds: float
) -> list[Sample]:
    out: list[Sample] = []
    end = time.monotonic() + seconds
    await asyncio.gather(*(_connection(host, port, tiles, end, random.Random(i), out) for i in range(connections)))
    return out


def run_client(
    host: str,
    port: int,
    tiles: list[tuple[int, int, int]],
    connections: int,
    seconds: float,
    niceness: int,
    conn: Connection,
) -> None:
    """Process entry: keep ``connections`` connections busy for ``seconds``; send the samples and this
    process's CPU seconds back."""
    if niceness:
        os.nice(niceness)
    samples = asyncio.run(_run(host, port, tiles, connections, seconds))
    times = os.times()
    conn.send((samples, times.user + times.system))


def summarize(samples: list[Sample]) -> dict[str, tuple[list[float], dict[int, int]]]:
    """Per label: latencies and status counts."""
    lat: dict[str, list[float]] = defaultdict(list)
    status: dict[str, dict[int, int]] = defaultdict(lambda: defaultdict(int))
    for label, seconds, code in samples:
        lat[label].append(seconds)
        status[label][code] += 1
    return {label: (lat[label], dict(status[label])) for label in lat}
