"""Static export: the pyramid of morph tiles of a stored dataset, written to a PMTiles or MBTiles archive.

The tiles are those a server would send (``Renderer.morph_tile``; ``docs/morph-tiles.md``), gzip-compressed,
for every tile of the zoom range that meets the dataset's bounds; empty tiles are left out. They are rendered
on every core: worker processes each open the store read-only with their own :class:`Renderer` and render
batches of tiles in PMTiles tile-id order; this process writes the batches in that order as they come back (a
bounded window of batches in flight), so the PMTiles archive is clustered and memory stays small.
"""

from __future__ import annotations

import gzip
import math
import os
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from html import escape
from pathlib import Path
from typing import Any

import numpy as np

from engine.cartography.dataset import DatasetCartography, contour_fields, label_fields
from engine.ccsm.build import default_workers
from engine.errors import InvalidParameter, StoreError
from engine.serve.label_layer import LABEL_LAYER
from engine.serve.morph_tiles import MORPH_END_LAYER, MORPH_START_LAYER, MORPH_T_SAMPLES
from engine.serve.renderer import Renderer
from engine.serve.tile_request import TileOptions
from engine.store.records import DatasetInfo
from engine.store.store import CCSStore
from engine.tiles.archives import ArchiveMeta, archive_format, open_archive, tile_id
from engine.tiles.grid import Tile, mercator_to_lonlat, tiles_covering
from engine.tiles.scale import zoom_for_scale
from engine.types import Bounds

Progress = Callable[[int, int], None]

#: zlib level of the tiles (6: zlib's default, as tile servers and tippecanoe use).
GZIP_LEVEL = 6
#: Batches in flight per worker (keeps every core busy while the writer waits for the next batch in order).
BATCHES_PER_WORKER = 4

#: The ``ccsm_morph`` member of the TileJSON (docs/morph-tiles.md).
CCSM_MORPH = {
    "version": 1,
    "t_samples": MORPH_T_SAMPLES,
    "start_layer": MORPH_START_LAYER,
    "end_layer": MORPH_END_LAYER,
}
ATTRIBUTION = "Contours: ccsm"
DESCRIPTION = "Terrain contours generalized continuously with the zoom (CCSM, Qian et al. 2021): morph tiles."


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: the archive, its format, tiles written and left out (empty), bytes, seconds."""

    path: Path
    format: str
    tiles: int
    empty: int
    bytes: int
    seconds: float
    minzoom: int
    maxzoom: int


def check_zoom_range(minzoom: int, maxzoom: int, limit: int | None = None) -> tuple[int, int]:
    """Validate an export's zoom range: ``0 <= minzoom <= maxzoom <= limit`` (the served range, 16).

    Raises
    ------
    InvalidParameter
        The message names the bad value.
    """
    limit = TileOptions().max_zoom if limit is None else limit
    if minzoom < 0:
        raise InvalidParameter(f"--minzoom must be >= 0, got {minzoom}")
    if maxzoom > limit:
        raise InvalidParameter(f"--maxzoom must be <= {limit}, got {maxzoom}")
    if minzoom > maxzoom:
        raise InvalidParameter(f"--minzoom {minzoom} is greater than --maxzoom {maxzoom}")
    return int(minzoom), int(maxzoom)


def pyramid(bounds_3857: Sequence[float], minzoom: int, maxzoom: int) -> list[Tile]:
    """Every tile of zooms ``minzoom`` .. ``maxzoom`` that meets the EPSG:3857 bounds, in tile-id order."""
    tiles = [t for z in range(minzoom, maxzoom + 1) for t in tiles_covering(Bounds(*bounds_3857), z)]
    tiles.sort(key=lambda t: tile_id(*t))
    return tiles


def lonlat_bounds(info: DatasetInfo) -> tuple[float, float, float, float]:
    """(west, south, east, north) of a dataset, degrees, 7 decimals."""
    minx, miny, maxx, maxy = info.bounds_3857
    lon, lat = mercator_to_lonlat(np.array([minx, maxx]), np.array([miny, maxy]))
    return (round(float(lon[0]), 7), round(float(lat[0]), 7), round(float(lon[1]), 7), round(float(lat[1]), 7))


def morph_vector_layers(minzoom: int, maxzoom: int, carto: DatasetCartography) -> list[dict[str, Any]]:
    """TileJSON ``vector_layers`` of morph tiles: ``contours`` with its fields, ``contours_end`` without,
    ``contour_labels`` with its fields."""
    fields = {
        **contour_fields(carto),
        "t": "Number: generalization parameter at the tile's zoom z (0 = source detail, 1 = the target)",
        **{f"t{k}": f"Number: t at zoom z + {k}/{MORPH_T_SAMPLES}" for k in range(1, MORPH_T_SAMPLES + 1)},
        "min_zoom": "Number: draw the contour only where zoom > min_zoom (absent: the whole level)",
    }
    return [
        {
            "id": MORPH_START_LAYER,
            "description": "Contours as at the tile's zoom z; each feature id is stable across zooms.",
            "minzoom": minzoom,
            "maxzoom": maxzoom,
            "fields": fields,
        },
        {
            "id": MORPH_END_LAYER,
            "description": "The same contours (same ids, parts and points) as at zoom z + 1.",
            "minzoom": minzoom,
            "maxzoom": maxzoom,
            "fields": {},
        },
        {
            "id": LABEL_LAYER,
            "description": "Label anchors on index contours, fixed per contour (they hold still while lines morph).",
            "minzoom": minzoom,
            "maxzoom": maxzoom,
            "fields": label_fields(carto),
        },
    ]


def archive_meta(info: DatasetInfo, carto: DatasetCartography, minzoom: int, maxzoom: int) -> ArchiveMeta:
    """The archive metadata of an export: bounds, centre, layers, ``ccsm_morph`` and the dataset's provenance."""
    bounds = lonlat_bounds(info)
    lat = (bounds[1] + bounds[3]) / 2
    start = int(round(float(zoom_for_scale(info.source_scale, max(-85.0, min(85.0, lat))))) - 1)
    center = (round((bounds[0] + bounds[2]) / 2, 7), round(lat, 7), min(maxzoom, max(minzoom, start)))
    return ArchiveMeta(
        name=info.name,
        description=DESCRIPTION,
        attribution=escape(carto.options.attribution or f"{ATTRIBUTION}, from {info.source}"),
        minzoom=minzoom,
        maxzoom=maxzoom,
        bounds=bounds,
        center=center,
        vector_layers=morph_vector_layers(minzoom, maxzoom, carto),
        extra={
            "ccsm_morph": dict(CCSM_MORPH),
            "ccsm_cartography": carto.as_json(),
            "ccsm": {
                "dataset": info.id,
                "data_version": info.data_version,
                "source": info.source,
                "source_hash": info.source_hash,
                "source_scale": info.source_scale,
                "target_scale": info.target_scale,
            },
        },
    )


# -- rendering (in the worker processes, or here with one worker) ------------------------------------------
Rendered = list[tuple[int, int, int, bytes]]


def render_batch(renderer: Renderer, dataset: str, tiles: Sequence[Tile]) -> Rendered:
    """The non-empty morph tiles of a batch, gzip-compressed, in the batch's order."""
    out: Rendered = []
    for z, x, y in tiles:
        result = renderer.morph_tile(dataset, z, x, y)
        if result.data is not None:
            out.append((z, x, y, gzip.compress(result.data, compresslevel=GZIP_LEVEL, mtime=0)))
    return out


def _render_version(renderer: Renderer, dataset: str, version: int, tiles: Sequence[Tile]) -> Rendered:
    """``render_batch``, provided the dataset is still the version the export started with.

    Raises
    ------
    StoreError
        The dataset was rebuilt or deleted during the export (its tiles would mix two versions).
    """
    now = renderer.store.data_version(dataset)
    if now != version:
        raise StoreError(f"dataset {dataset} changed during the export (data_version {version} -> {now}); run it again")
    return render_batch(renderer, dataset, tiles)


_worker: dict[str, Any] = {}


def _init_worker(store_path: str, dataset: str, version: int) -> None:
    """Each worker process: its own read-only store connection and renderer."""
    _worker["renderer"] = Renderer(CCSStore(store_path, readonly=True))
    _worker["dataset"] = dataset
    _worker["version"] = version


def _render_in_worker(tiles: list[Tile]) -> Rendered:
    return _render_version(_worker["renderer"], _worker["dataset"], _worker["version"], tiles)


def _batches(tiles: list[Tile], size: int) -> list[list[Tile]]:
    return [tiles[i : i + size] for i in range(0, len(tiles), size)]


def _ordered(pool: ProcessPoolExecutor, batches: list[list[Tile]], window: int) -> Iterator[Rendered]:
    """Results of the batches in their order, with at most ``window`` batches submitted ahead."""
    pending: deque[Future[Rendered]] = deque()
    todo = iter(batches)
    for batch in todo:
        pending.append(pool.submit(_render_in_worker, batch))
        if len(pending) >= window:
            break
    while pending:
        result = pending.popleft().result()
        nxt = next(todo, None)
        if nxt is not None:
            pending.append(pool.submit(_render_in_worker, nxt))
        yield result


def export_dataset(
    store_path: str | os.PathLike[str],
    dataset: str,
    out: str | os.PathLike[str],
    *,
    minzoom: int = 0,
    maxzoom: int = 14,
    workers: int | None = None,
    batch_size: int | None = None,
    progress: Progress | None = None,
) -> ExportResult:
    """Write the morph tiles of a stored dataset over its bounds, zooms ``minzoom`` .. ``maxzoom``, to ``out``.

    Parameters
    ----------
    store_path
        The store (opened read-only, here and in every worker).
    out
        ``*.pmtiles`` or ``*.mbtiles``; written to a temporary file beside it and renamed when complete.
    workers
        Processes rendering tiles (None = one per core; 1 = in this process).
    batch_size
        Tiles per task (None: about 16 tasks per worker, at most 64 tiles each).
    progress
        Called with (tiles done, tiles in the pyramid).

    Raises
    ------
    InvalidParameter
        Bad zoom range, unknown extension, unwritable target or no tile to write (``out`` left as it was).
    UnknownLayer, StoreError
        The dataset is not in the store, the store cannot be opened, or the dataset changed during the export.
    """
    started = time.perf_counter()
    fmt = archive_format(out)
    minzoom, maxzoom = check_zoom_range(minzoom, maxzoom)
    renderer = Renderer(CCSStore(store_path, readonly=True))
    info, _ = renderer.info(dataset)
    tiles = pyramid(info.bounds_3857, minzoom, maxzoom)
    workers = default_workers() if workers is None else max(1, workers)
    workers = min(workers, max(1, len(tiles)))
    if batch_size is None:
        batch_size = max(1, min(64, math.ceil(len(tiles) / (16 * workers))))
    batches = _batches(tiles, batch_size)
    archive = open_archive(out)
    done = 0
    if progress:
        progress(0, len(tiles))
    try:
        if workers == 1:
            version = info.data_version
            results: Iterator[Rendered] = (_render_version(renderer, dataset, version, b) for b in batches)
            pool = None
        else:
            pool = ProcessPoolExecutor(
                max_workers=workers, initializer=_init_worker, initargs=(str(store_path), dataset, info.data_version)
            )
            results = _ordered(pool, batches, BATCHES_PER_WORKER * workers)
        try:
            for batch, rendered in zip(batches, results, strict=True):
                for z, x, y, data in rendered:
                    archive.add(z, x, y, data)
                done += len(batch)
                if progress:
                    progress(done, len(tiles))
        finally:
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
        size = archive.commit(archive_meta(info, renderer.cartography(dataset), minzoom, maxzoom))
    except BaseException:
        archive.abort()
        raise
    return ExportResult(
        Path(out), fmt, archive.tiles, len(tiles) - archive.tiles, size, time.perf_counter() - started, minzoom, maxzoom
    )
