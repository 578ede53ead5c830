"""Big-region benchmark (issue 12 item 6): build time, vertices/s/core, peak memory, store size and tile times
as the data grows, on generated terrain, on denser intervals of one DEM, and on thousands of short rings.

Every build runs in its own process (``--one``), so its peak memory is its own: the build process's peak RSS
and the largest peak of its pool workers are printed apart. The DEMs are fractal terrain (tests'
``fractal_heights``) written as tiled GeoTIFFs and read in windows of 512 cells.

Series
------
``grid``   the same kind of terrain on a grid 2× and 4× as wide (4× and 16× the vertices): lines cross as in
           real data, so the crossing repair's cost shows (copies side by side would hide it).
``dense``  one DEM at 20, 10 and 5 m intervals: more lines in the same place.
``short``  thousands of small hills: rings of a few dozen vertices, the costliest contours per vertex.

Usage: python bench/bench_scale.py [--sizes 1,4,16] [--workers 2] [--series sample,grid,dense,short] [--cache-mb MB]
       python bench/bench_scale.py --tiles STORE[,STORE...] [--cache-mb MB[,MB...]] [--mmap-mb MB]   (tile times only)
(each build runs once; on a loaded 2-core machine 4× takes about ten minutes, 16× far longer)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rasterio

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

WORK = REPO / "var" / "bench-scale"
CELL_M = 30.0
#: Grid side of the 1× terrain; 2× and 4× the side give 4× and 16× the vertices.
BASE_SIDE = 512


def write_dem(path: Path, z: np.ndarray) -> Path:
    """A tiled GeoTIFF in UTM 16N (256-cell internal tiles, as a COG has)."""
    profile = {
        "driver": "GTiff",
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": "float32",
        "crs": "EPSG:32616",
        "transform": rasterio.Affine(CELL_M, 0.0, 740_000.0, 0.0, -CELL_M, 4_060_000.0),
        "tiled": True,
        "blockxsize": 256,
        "blockysize": 256,
    }
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(z.astype(np.float32), 1)
    return path


def terrain(side: int) -> np.ndarray:
    """Fractal terrain whose relief grows with the side, so a larger grid holds as many lines per km²."""
    from synthetic_rasters import fractal_heights

    return fractal_heights(21, 3.6, n=side, relief_m=800.0 * side / BASE_SIDE)


def short_hills(side: int, seed: int = 4) -> np.ndarray:
    """Thousands of small round hills on a flat plain: each a few rings of a few dozen vertices."""
    rng = np.random.default_rng(seed)
    r, c = np.mgrid[0:side, 0:side].astype(np.float64)
    z = np.full((side, side), 100.0)
    for _ in range(side * side // 60):
        r0, c0 = rng.uniform(0, side, 2)
        radius = rng.uniform(1.5, 3.5)
        near = (np.abs(r - r0) < 4 * radius) & (np.abs(c - c0) < 4 * radius)
        z[near] += 45.0 * np.exp(-((r[near] - r0) ** 2 + (c[near] - c0) ** 2) / (2 * radius**2))
    return np.round(z)


def datasets(sizes: list[int]) -> list[tuple[str, str, Path, float]]:
    """(series, label, DEM, interval) of every build to run, the DEMs written once into var/bench-scale."""
    from engine.io.source import sample_contours_path

    WORK.mkdir(parents=True, exist_ok=True)
    out = [("sample", "bundled", sample_contours_path(), 0.0)]
    for k in sizes:
        side = int(BASE_SIDE * np.sqrt(k))
        path = WORK / f"terrain-{side}.tif"
        if not path.exists():
            write_dem(path, terrain(side))
        out.append(("grid", f"{k}x", path, 20.0))
    base = WORK / f"terrain-{BASE_SIDE}.tif"
    for interval in (10.0, 5.0):
        if max(sizes) >= 4 or interval == 10.0:
            out.append(("dense", f"{20 / interval:g}x lines", base, interval))
    hills = WORK / "hills-384.tif"
    if not hills.exists():
        write_dem(hills, short_hills(384))
    out.append(("short", "rings", hills, 10.0))
    return out


def peak_rss_mb() -> float:
    """This process's peak resident memory (VmHWM), MB. Not ``ru_maxrss``: Linux carries that over fork and exec,
    so a build started after the bench generated a large DEM reported the bench's own peak."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def build_one(path: Path, interval: float, workers: int, cache_mb: float | None = None) -> dict[str, float]:
    """Build one DEM into a fresh store (this process); the numbers as a dict.

    The phases are timed by wrapping the functions that do them (nothing else changes); the peak memory is read
    right after the build, before the tiles are timed (the renderer then loads the whole dataset to serve it).
    """
    import engine.build.datasets as datasets_module
    import engine.ccsm.build as build_module
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.store.store import CCSStore

    phase_s = {"read": 0.0, "repair": 0.0, "write": 0.0}
    peak_mb = {}  # the build process's peak RSS when each phase ended

    def timed(phase: str, fn):  # noqa: ANN001, ANN202 - wraps any function, changes nothing
        def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                phase_s[phase] += time.perf_counter() - t0
                peak_mb[phase] = peak_rss_mb()

        return wrapper

    build_module.resolve_crossings = timed("repair", build_module.resolve_crossings)
    datasets_module.read_source = timed("read", datasets_module.read_source)
    CCSStore.save = timed("write", CCSStore.save)  # type: ignore[method-assign]
    store_path = WORK / f"{path.stem}-{interval:g}.sqlite"
    for stale in WORK.glob(f"{store_path.name}*"):
        stale.unlink()
    store = CCSStore(store_path)
    dem = path.suffix == ".tif"
    spec = SourceSpec(path, "bench", path.stem, interval=interval if dem else None, block=512 if dem else None)
    from app.cli.commands_service import build_executor

    t0 = time.perf_counter()
    with build_executor(None, workers) as executor:
        info, _ = build_dataset(store, spec, workers=workers, executor=executor, force=True)
    seconds = time.perf_counter() - t0
    rss_main = peak_rss_mb()
    rss_worker = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    store.close()
    p50, p95 = tile_times(store_path, cache_mb=cache_mb)
    return {
        "contours": info.n_contours,
        "vertices": info.n_vertices,
        "seconds": seconds,
        "read_s": phase_s["read"],
        "repair_s": phase_s["repair"],
        "write_s": phase_s["write"],
        "rss_main_mb": rss_main,
        "rss_read_mb": peak_mb.get("read", 0.0),
        "rss_worker_mb": rss_worker,
        "store_mb": store_path.stat().st_size / 1e6,
        "tile_p50_ms": p50,
        "tile_p95_ms": p95,
    }


def tile_times(store_path: Path, n: int = 120, cache_mb: float | None = None) -> tuple[float, float]:
    """p50 and p95 of rendering ``n`` distinct z12-z14 tiles of the store (ms of wall time, the first tile
    included), read by a new renderer with ``cache_mb`` of contour memory (None: the renderer's default)."""
    times = tile_run(store_path, n, cache_mb)["wall_ms"]
    return float(np.percentile(times, 50)), float(np.percentile(times, 95))


def tile_run(
    store_path: Path, n: int = 120, cache_mb: float | None = None, mmap_mb: float = 0.0
) -> dict[str, np.ndarray]:
    """Wall and CPU milliseconds of each of ``n`` distinct z12-z14 tiles of the store's first dataset, in the
    order rendered by one new renderer (the first tile is the first request of the data version: it pays for
    what a renderer does once per version, e.g. reading the label anchors), its store read through ``mmap_mb``
    of memory mapping (as a render worker's, CCSM_STORE_MMAP_MB; 0: none)."""
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    store = CCSStore(store_path, readonly=True, mmap_bytes=int(mmap_mb * 2**20))
    dataset = store.dataset_ids()[0]
    info = store.dataset(dataset)
    tiles = [t for z in (12, 13, 14) for t in tiles_covering(Bounds(*info.bounds_3857), z)]
    rng = np.random.default_rng(0)
    chosen = [tiles[i] for i in rng.choice(len(tiles), size=min(n, len(tiles)), replace=False)]
    renderer = Renderer(store) if cache_mb is None else Renderer(store, contour_cache_bytes=int(cache_mb * 2**20))
    renderer.pack(dataset)  # the per-dataset pack is loaded once per process, not per tile
    wall, cpu = [], []
    for z, x, y in chosen:
        t0, c0 = time.perf_counter(), time.process_time()
        renderer.tile(dataset, z, x, y)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"wall_ms": np.array(wall) * 1000, "cpu_ms": np.array(cpu) * 1000}


def print_tile_runs(stores: list[Path], cache_mb: list[float | None], mmap_mb: float = 0.0) -> None:
    """Tile times of existing stores (no build), one line per store: first tile, then p50 / p95 of the
    others, wall and CPU."""
    print(f"{'store':28} {'cache MB':>8} {'first s':>8} {'p50 ms':>7} {'p95 ms':>7} {'cpu p50':>7} {'cpu p95':>7}")
    for path, mb in zip(stores, cache_mb, strict=True):
        r = tile_run(path, cache_mb=mb, mmap_mb=mmap_mb)
        wall, cpu = r["wall_ms"][1:], r["cpu_ms"][1:]
        print(
            f"{path.name:28} {'default' if mb is None else f'{mb:g}':>8} {r['wall_ms'][0] / 1000:8.2f} "
            f"{np.percentile(wall, 50):7.2f} {np.percentile(wall, 95):7.2f} "
            f"{np.percentile(cpu, 50):7.2f} {np.percentile(cpu, 95):7.2f}",
            flush=True,
        )


def run_child(path: Path, interval: float, workers: int, cache_mb: float | None) -> dict[str, float]:
    cache = [] if cache_mb is None else ["--cache-mb", f"{cache_mb:g}"]
    out = subprocess.run(
        [sys.executable, __file__, "--one", str(path), "--interval", str(interval), "--workers", str(workers), *cache],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="1,4,16", help="Multiples of the 1× terrain's vertices.")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--series", default="sample,grid,dense,short", help="Which series to run.")
    parser.add_argument(
        "--cache-mb",
        default="",
        help="Contour memory of the renderer timing the tiles (MB; default the renderer's); a dataset larger "
        "than it is packed per tile. With --tiles: one value per store, comma-separated (empty: default).",
    )
    parser.add_argument(
        "--tiles",
        help="Time the tiles of existing stores (comma-separated paths) instead of building; no build.",
    )
    parser.add_argument(
        "--mmap-mb", type=float, default=0.0, help="With --tiles: the store read through memory mapping (MB; 0: none)."
    )
    parser.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--interval", type=float, default=20.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    cache_mb = [float(v) if v else None for v in args.cache_mb.split(",")]
    if args.one:
        print(json.dumps(build_one(args.one, args.interval, args.workers, cache_mb[0])))
        return
    if args.tiles:
        stores = [Path(p) for p in args.tiles.split(",")]
        print_tile_runs(stores, cache_mb if len(cache_mb) == len(stores) else cache_mb[:1] * len(stores), args.mmap_mb)
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    print(
        f"{args.workers} build workers; sizes relative to the 1x terrain's vertices; read / repair / write: shares "
        "of the build time; RSS: peak of the build process once the source is read and after the build, and of its "
        "largest worker (MB, before the tiles are timed)"
    )
    header = (
        f"{'series':7} {'data':11} {'contours':>8} {'vertices':>9} {'build s':>8} {'read':>5} {'repair':>6} "
        f"{'write':>5} {'vert/s/core':>11} {'µs/vertex':>9} {'RSS read':>8} {'RSS main':>8} {'RSS wkr':>8} "
        f"{'store MB':>8} "
        f"{'tile p50':>8} {'p95 ms':>7}"
    )
    print(header)
    wanted = set(args.series.split(","))
    for series, label, path, interval in datasets(sizes):
        if series not in wanted:
            continue
        r = run_child(path, interval, args.workers, cache_mb[0])
        per_core = r["vertices"] / r["seconds"] / args.workers
        print(
            f"{series:7} {label:11} {r['contours']:8.0f} {r['vertices']:9.0f} {r['seconds']:8.1f} "
            f"{r['read_s'] / r['seconds']:5.0%} {r['repair_s'] / r['seconds']:6.0%} {r['write_s'] / r['seconds']:5.0%} "
            f"{per_core:11.0f} {1e6 / per_core:9.1f} "
            f"{r['rss_read_mb']:8.0f} {r['rss_main_mb']:8.0f} {r['rss_worker_mb']:8.0f} {r['store_mb']:8.1f} "
            f"{r['tile_p50_ms']:8.2f} {r['tile_p95_ms']:7.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
