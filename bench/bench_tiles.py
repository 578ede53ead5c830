"""Tile service benchmark on the bundled sample: prints the numbers of issue 3, item 8.

1. Uncached tile latency (no ETag; every request renders) p50/p95 per zoom, z8-z15, over HTTP (1 worker).
2. Tiles per second with 1 and 2 uvicorn workers over loopback (8 concurrent clients).
3. Cached requests per second (If-None-Match -> 304).
4. Server memory (RSS of the uvicorn processes).
5. The full z0-z15 pyramid of the sample, in process, against geojson-vt + vt-pbf (node) on the same tiles.
6. Tile time at 1x and 16x data (the sample repeated 4 x 4): the same tiles, the same work.

Usage: python bench/bench_tiles.py [--quick]   (needs `npm ci` in bench/geojsonvt for step 5)
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from engine.build.datasets import save_built  # noqa: E402
from engine.ccsm.build import build_contour_set  # noqa: E402
from engine.io.source import read_source, sample_contours_path  # noqa: E402
from engine.serve.renderer import Renderer  # noqa: E402
from engine.store.store import CCSStore  # noqa: E402
from engine.tiles.grid import tiles_covering  # noqa: E402
from engine.types import Bounds, Contour  # noqa: E402
from tests.app.conftest import LiveServer  # noqa: E402

WORK = REPO / "var" / "bench"


def build_stores() -> tuple[Path, Path]:
    """The sample at 1x and 16x (4 x 4 copies 40 km apart, built once and translated)."""
    WORK.mkdir(parents=True, exist_ok=True)
    one, many = WORK / "sample-1x.sqlite", WORK / "sample-16x.sqlite"
    if one.exists() and many.exists():
        return one, many
    cs = read_source(sample_contours_path())
    t0 = time.perf_counter()
    built = build_contour_set(cs)
    print(f"build of the sample: {time.perf_counter() - t0:.1f} s ({len(built.surfaces)} contours)")
    save_built(CCSStore(one), "sample", built, name="sample", source="sample", digest="1x", params={})
    surfaces, inputs = [], []
    for i in range(4):
        for j in range(4):
            off = np.array([i * 40_000.0, j * 40_000.0])
            for s, c in zip(built.surfaces, built.inputs, strict=True):
                surfaces.append(
                    dataclasses.replace(s, contour_id=f"{i}{j}:{s.contour_id}", base=s.base + off, top=s.top + off)
                )
                inputs.append(Contour(f"{i}{j}:{c.id}", c.elevation, c.coords + off, c.closed))
    big = dataclasses.replace(built, surfaces=surfaces, inputs=inputs)
    save_built(CCSStore(many), "sample", big, name="sample16", source="sample", digest="16x", params={})
    return one, many


def pyramid(info_bounds: tuple[float, float, float, float], zooms: range) -> list[tuple[int, int, int]]:
    return [tuple(t) for z in zooms for t in tiles_covering(Bounds(*info_bounds), z)]  # type: ignore[misc]


def pct(values: list[float]) -> str:
    a = np.array(values) * 1000
    return f"p50 {np.percentile(a, 50):6.2f} ms  p95 {np.percentile(a, 95):6.2f} ms  max {a.max():7.2f} ms"


class Server(LiveServer):
    """The service on ``store`` with ``workers`` uvicorn workers (no sample, no builds), answering."""

    def __init__(self, store: Path, workers: int) -> None:
        env = {"CCSM_STORE_PATH": str(store), "CCSM_SERVE_SAMPLE": "false", "CCSM_BUILD_ON_START": "false"}
        super().__init__(env, args=["--workers", str(workers)])
        self.wait_healthy()
        time.sleep(0.5 * workers)

    def rss_mb(self) -> float:
        pids = [self.proc.pid]
        try:
            out = subprocess.run(["pgrep", "-P", str(self.proc.pid)], capture_output=True, text=True).stdout
            pids += [int(p) for p in out.split()]
        except FileNotFoundError:
            pass
        total = 0
        for pid in pids:
            try:
                for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1])
            except OSError:
                pass
        return total / 1024


async def throughput(url: str, paths: list[str], concurrency: int = 8, headers: dict | None = None) -> float:
    queue = list(paths)
    async with httpx.AsyncClient(base_url=url, timeout=60, limits=httpx.Limits(max_connections=concurrency)) as c:

        async def worker() -> None:
            while queue:
                p = queue.pop()
                r = await c.get(p, headers=headers)
                assert r.status_code in (200, 204, 304), r.status_code

        t0 = time.perf_counter()
        await asyncio.gather(*(worker() for _ in range(concurrency)))
        return len(paths) / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="z8-z13 only for the HTTP parts")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f}")
    one, many = build_stores()
    r1 = Renderer(CCSStore(one))
    info, _ = r1.info("sample")
    zooms = range(8, 14 if args.quick else 16)
    tiles = pyramid(info.bounds_3857, zooms)
    paths = [f"/tiles/sample/{z}/{x}/{y}.mvt" for z, x, y in tiles]
    print(f"\n== uncached tile latency over HTTP, 1 worker, z{zooms.start}-z{zooms.stop - 1} ({len(tiles)} tiles) ==")
    srv = Server(one, 1)
    try:
        with httpx.Client(base_url=srv.url, timeout=60) as c:
            for p in paths:  # warm the per-process contour cache once (disk -> memory), as a running server is
                c.get(p)
            per_zoom: dict[int, list[float]] = {}
            for (z, _, _), p in zip(tiles, paths, strict=True):
                t0 = time.perf_counter()
                r = c.get(p)
                per_zoom.setdefault(z, []).append(time.perf_counter() - t0)
                assert r.status_code in (200, 204)
            for z, v in per_zoom.items():
                print(f"z{z:<2} {len(v):5d} tiles  {pct(v)}")
            print(f"all {len(tiles):5d} tiles  {pct([x for v in per_zoom.values() for x in v])}")
            etag_paths = []
            for p in paths[:500]:
                r = c.get(p)
                if "etag" in r.headers:
                    etag_paths.append((p, r.headers["etag"]))
        rps1 = asyncio.run(throughput(srv.url, paths * 2))
        cached = asyncio.run(throughput(srv.url, [p for p, _ in etag_paths] * 20, headers={"if-none-match": "*"}))
        mem1 = srv.rss_mb()
    finally:
        srv.stop()
    srv2 = Server(one, 2)
    try:
        asyncio.run(throughput(srv2.url, paths))  # warm both workers
        rps2 = asyncio.run(throughput(srv2.url, paths * 2))
        mem2 = srv2.rss_mb()
    finally:
        srv2.stop()
    print("\n== throughput over loopback (8 concurrent clients, each request renders) ==")
    print(f"1 worker : {rps1:7.1f} tiles/s   server RSS {mem1:6.0f} MB")
    print(f"2 workers: {rps2:7.1f} tiles/s   server RSS {mem2:6.0f} MB (both workers)")
    print(f"cached (If-None-Match -> 304), 1 worker: {cached:7.1f} requests/s")

    print("\n== full z0-z15 pyramid of the sample, in process, vs geojson-vt ==")
    full = pyramid(info.bounds_3857, range(0, 16))
    # A serving process has loaded its compiled kernels long before; load them here too (numba's one-off
    # per-process start, a few tenths of a second) so that "cold" means an empty store cache, not a new process.
    t0 = time.perf_counter()
    Renderer(CCSStore(one)).tile("sample", *full[-1])
    print(f"(kernels loaded in this process: {time.perf_counter() - t0:.2f} s, not counted)")
    cold = Renderer(CCSStore(one))
    t0 = time.perf_counter()
    n_ok = sum(cold.tile("sample", *t).data is not None for t in full)
    t_cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    for t in full:
        cold.tile("sample", *t)
    t_warm = time.perf_counter() - t0
    print(f"ccsm      : {len(full)} tiles ({n_ok} non-empty): {t_cold:6.2f} s cold store, {t_warm:6.2f} s warm")
    node_dir = REPO / "bench" / "geojsonvt"
    if shutil.which("node") and (node_dir / "node_modules" / "geojson-vt").is_dir():
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as fh:
            json.dump(full, fh)
        out = subprocess.run(
            ["node", str(node_dir / "tile_pyramid.mjs"), str(sample_contours_path()), fh.name],
            capture_output=True,
            text=True,
            check=True,
        )
        gv = json.loads(out.stdout)
        g = gv["total_ms"] / 1000
        print(
            f"geojson-vt: {gv['tiles']} tiles ({gv['non_empty']} non-empty): {g:6.2f} s "
            f"(index {gv['index_ms'] / 1000:.2f} s + tiles and vt-pbf {gv['tiles_ms'] / 1000:.2f} s; JSON parse "
            f"{gv['parse_ms'] / 1000:.2f} s not counted)"
        )
        print(f"ratio ccsm / geojson-vt: {t_cold / g:.2f} (cold), {t_warm / g:.2f} (warm); goal <= 2")
    else:
        print("geojson-vt: skipped (run `npm ci` in bench/geojsonvt)")

    print("\n== tile time at 1x and 16x data (same tiles, z12-z14) ==")
    r16 = Renderer(CCSStore(many))
    same = pyramid(info.bounds_3857, range(12, 15))
    for name, r in (("1x", r1), ("16x", r16)):
        for t in same:
            r.tile("sample", *t)
        times = []
        for t in same:
            t0 = time.perf_counter()
            r.tile("sample", *t)
            times.append(time.perf_counter() - t0)
        n = r.info("sample")[0].n_contours
        print(f"{name:>3} ({n:6d} contours): {len(same)} tiles  {pct(times)}")


if __name__ == "__main__":
    main()
