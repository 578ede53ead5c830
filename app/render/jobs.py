"""What a render worker process does: open the store read-only, draw tiles, hillshade tiles and /simplify
answers.

This module runs inside the worker processes of :mod:`app.render.pool` (docs/service.md, "Under load").
It imports no web framework: a job is a plain tuple in, bytes (or an engine error) out.
"""

from __future__ import annotations

import json
import logging
import signal
import time
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from app.http.compression import gzip_body, worth_compressing
from engine.errors import CCSMError, UnknownLayer
from engine.parallel import lower_priority as lower_process_priority
from engine.serve.cache import LRUCache
from engine.serve.heads import DEFAULT_HEAD_CACHE_BYTES
from engine.serve.relief import ReliefCache
from engine.serve.renderer import Renderer, TileOptions
from engine.serve.simplify import feature_collection
from engine.serve.simplify import simplify as simplify_dataset
from engine.store.store import CCSStore
from engine.tiles.grid import Tile
from engine.tiles.hillshade import hillshade_tile

log = logging.getLogger("ccsm.render")

#: Niceness a light-lane worker adds to its own: when the cores are all busy, the server's event loop (little
#: work, and ``/healthz`` among it) runs before the workers' jobs rather than waiting for its turn among them.
LIGHT_NICENESS = 5
#: Niceness of the heavy lane's workers and of upload checks: below the light lane too, so map tiles (ms each)
#: keep their pace while whole-dataset and per-request simplifications run (a nice-10 process gets about a
#: third of a nice-5 one's share of a busy core).
HEAVY_NICENESS = 10


def lower_priority(niceness: int) -> None:
    """Add ``niceness`` to this process's; background work (``niceness`` at HEAVY_NICENESS or more: the heavy
    lane, upload checks) also takes the idle scheduling class (:func:`engine.parallel.lower_priority`)."""
    lower_process_priority(niceness, idle=niceness >= HEAVY_NICENESS)


#: Niceness of the morph lane's workers: morph tiles are map tiles too (the plugin's), so they share the light
#: lane's priority; their own lane is what keeps a plain tile from waiting behind them.
MORPH_NICENESS = LIGHT_NICENESS


@dataclass(frozen=True)
class RenderConfig:
    """What a worker needs from the settings (plain values: it crosses a process boundary)."""

    store_path: Path
    tile: TileOptions
    contour_cache_bytes: int
    baseline_cache_entries: int
    wm_max_vertices: int
    morph_cache_bytes: int = 0
    head_cache_bytes: int = DEFAULT_HEAD_CACHE_BYTES
    store_mmap_bytes: int = 0


@dataclass(frozen=True)
class _TileAddress:
    """Which tile of which dataset: what every tile job starts with."""

    dataset: str
    z: int
    x: int
    y: int


@dataclass(frozen=True)
class TileJob(_TileAddress):
    """One per-level tile (every method)."""

    zoom: float
    method: str
    t: float | None
    store: Path | None = None  # the store file the request's service reads (replicas switch files)
    gzip: bool = False  # the client accepts gzip: compress here, off the server's event loop


@dataclass(frozen=True)
class MorphJob(_TileAddress):
    """One morph tile."""

    store: Path | None = None  # the store file the request's service reads (replicas switch files)
    gzip: bool = False  # the client accepts gzip: compress here, off the server's event loop


@dataclass(frozen=True)
class HillshadeJob(_TileAddress):
    """One hillshade PNG tile of the DEM a dataset was made from (or given with)."""

    store: Path | None = None  # the store file the request's service reads (replicas switch files)


@dataclass(frozen=True)
class SimplifyJob:
    """Every contour of a dataset at a scale, as GeoJSON bytes."""

    dataset: str
    scale: float
    bbox: list[float] | None
    method: str
    all_levels: bool = False  # keep the levels the interval schedule no longer draws at this scale
    store: Path | None = None  # the store file the request's service reads (replicas switch files)
    gzip: bool = False  # the client accepts gzip: compress here, off the server's event loop


@dataclass(frozen=True)
class Rendered:
    """A job's answer: the body (None for an empty tile), the scale it was drawn at, and whether the body is
    gzipped; with the seconds it waited for a worker and the seconds the worker spent on it (the pool fills
    both; the tile routes send them as ``Server-Timing``, so a load test can tell queueing from work)."""

    body: bytes | None
    scale: float
    gzipped: bool = False
    wait_s: float = 0.0
    work_s: float = 0.0


def compressed(rendered: Rendered) -> Rendered:
    """The answer with its body gzipped, when it is worth it."""
    if rendered.body is None or not worth_compressing(rendered.body):
        return rendered
    return replace(rendered, body=gzip_body(rendered.body), gzipped=True)


Job = TileJob | MorphJob | HillshadeJob | SimplifyJob


#: A morph tile's cache key: dataset, data version, z, x, y.
MorphKey = tuple[str, int, int, int, int]


@dataclass
class Worker:
    """What one worker keeps between jobs: its renderer (store, caches), the shaded reliefs, and the morph
    tiles it drew (a morph tile depends only on the dataset's data version and the tile, and its crossing
    check is the slow part: decided once per version and tile, not per request)."""

    renderer: Renderer
    reliefs: ReliefCache
    morph_tiles: LRUCache[MorphKey, Rendered]

    @classmethod
    def of(cls, config: RenderConfig, store_path: Path | None = None) -> Worker:
        """A fresh worker state on ``store_path`` (default: the configured store)."""
        morph_tiles: LRUCache[MorphKey, Rendered] = LRUCache(config.morph_cache_bytes, morph_tile_cost)
        return cls(make_renderer(config, store_path), ReliefCache(), morph_tiles)


def morph_tile_cost(rendered: Rendered) -> int:
    """Bytes a cached morph tile holds (its body and some overhead)."""
    return len(rendered.body or b"") + 256


def make_renderer(config: RenderConfig, store_path: Path | None = None) -> Renderer:
    """The worker's own store connection and renderer (caches are per worker)."""
    return Renderer(
        CCSStore(store_path or config.store_path, mmap_bytes=config.store_mmap_bytes),
        config.tile,
        contour_cache_bytes=config.contour_cache_bytes,
        head_cache_bytes=config.head_cache_bytes,
        baseline_cache_entries=config.baseline_cache_entries,
        baseline_max_vertices={"wm": config.wm_max_vertices},
    )


def run_job(worker: Worker, job: Job) -> Rendered:
    """Do one job."""
    renderer = worker.renderer
    if isinstance(job, TileJob):
        tile = renderer.tile(job.dataset, job.z, job.x, job.y, zoom=job.zoom, method=job.method, t=job.t)
        return Rendered(tile.data, tile.scale)
    if isinstance(job, MorphJob):
        return draw_morph(worker, job)
    if isinstance(job, HillshadeJob):
        return Rendered(draw_hillshade(worker, job), 0.0)
    result = simplify_dataset(
        renderer, job.dataset, job.scale, bbox_lonlat=job.bbox, method=job.method, all_levels=job.all_levels
    )
    doc = feature_collection(result.contours, job.scale, job.method, dropped=result.dropped)
    doc["dataset"] = job.dataset
    return Rendered(json.dumps(doc, separators=(",", ":"), allow_nan=False).encode(), job.scale)


def draw_morph(worker: Worker, job: MorphJob) -> Rendered:
    """A morph tile, drawn once per data version of its dataset in this worker (then from its cache)."""
    info, _ = worker.renderer.info(job.dataset)
    key = (job.dataset, info.data_version, job.z, job.x, job.y)
    cached = worker.morph_tiles.get(key)
    if cached is not None:
        return cached
    tile = worker.renderer.morph_tile(job.dataset, job.z, job.x, job.y)
    rendered = Rendered(tile.data, tile.scale)
    if worker.morph_tiles.max_cost > 0:
        worker.morph_tiles.put(key, rendered)
    return rendered


def draw_hillshade(worker: Worker, job: HillshadeJob) -> bytes | None:
    """The PNG of a hillshade tile (None when it misses the DEM); the dataset's relief is shaded once per data
    version in each worker.

    Raises
    ------
    UnknownLayer
        The dataset has no DEM to shade.
    """
    info, _ = worker.renderer.info(job.dataset)
    relief = worker.reliefs.relief(info)
    if relief is None:
        raise UnknownLayer(f"dataset {job.dataset!r} has no DEM to shade")
    return hillshade_tile(relief, Tile(job.z, job.x, job.y))


def warm(renderer: Renderer) -> None:
    """Pack every stored dataset (or read its contour heads, when it is too large to pack) and read its labels
    now (placing them only for a version stored without them), so that cost (seconds on a large dataset) is paid
    before the worker takes its first request, not inside one request's deadline."""
    for dataset in renderer.store.dataset_ids():
        try:
            if renderer.pack(dataset) is None:
                renderer.heads(dataset)  # too large to hold whole: its heads instead, when they fit
            renderer.labels(dataset)  # the build stored them: read once per data version
        except Exception:  # a dataset that cannot be packed fails in its own requests, with its own error
            log.warning("render worker: could not pack %s ahead of use", dataset, exc_info=True)


def worker_main(conn: Connection, config: RenderConfig, niceness: int = LIGHT_NICENESS) -> None:
    """A worker's loop: warm up, say ``ready``, then answer jobs until the pipe closes.

    Each answer is ``("ok", Rendered)`` or ``("error", exception)``. SIGINT is left to the server process,
    which stops its workers itself (so Ctrl-C does not print a traceback per worker).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    lower_priority(niceness)
    worker = Worker.of(config)
    renderer_store = config.store_path
    warm(worker.renderer)
    conn.send(("ready", None))
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):  # the server closed the pipe or went away
            return
        if job.store is not None and job.store != renderer_store:
            # The service moved to another store file (ccsm build --publish): its caches and data versions
            # belong to the old file, so the worker starts afresh on the new one.
            worker.renderer.store.close()
            worker, renderer_store = Worker.of(config, job.store), job.store
        try:
            began = time.perf_counter()
            rendered = run_job(worker, job)
            rendered = compressed(rendered) if getattr(job, "gzip", False) else rendered
            answer: tuple[str, Any] = ("ok", replace(rendered, work_s=time.perf_counter() - began))
        except CCSMError as exc:  # a domain error: the server answers with its status and message
            answer = ("error", exc)
        except Exception as exc:  # a bug: the server answers 500; the traceback is only here, in the log
            log.error("render job %r failed", job, exc_info=exc)
            answer = ("error", RuntimeError("render job failed (see the log)"))
        try:
            conn.send(answer)
        except Exception as exc:  # an exception that does not pickle: send what it says instead
            conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))
