"""Issue 12 item 6: a render worker holds the contour heads of a dataset too large to pack whole
(``CCSM_HEAD_CACHE_MB``, engine/serve/heads.py), read once per data version instead of per tile.

Tiles drawn with the heads held are those drawn reading them per tile; a rebuilt dataset (a new data version,
new fids) has its new heads read and drawn; a worker on another store file (replicas switch files; a fresh
store numbers its contours and versions from 1 again) never draws with the first store's heads.
A worker reads its store through memory mapping when configured to (``CCSM_STORE_MMAP_MB``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from app.render.jobs import MorphJob, RenderConfig, TileJob, Worker, run_job
from engine.build.datasets import SourceSpec, build_dataset
from engine.serve.renderer import TileOptions
from engine.store.store import CCSStore
from tests.app.conftest import LAT0, LON0, synthetic_features, write_geojson
from tests.app.helpers import tile_for

#: Contour memory too small to hold 'hills' whole: every tile is packed from the stored pieces it meets.
SMALL_CONTOUR_CACHE = 1 << 16


def config(store: Path, head_mb: float = 8) -> RenderConfig:
    return RenderConfig(
        store, TileOptions(), SMALL_CONTOUR_CACHE, 1000, 50_000, head_cache_bytes=int(head_mb * (1 << 20))
    )


def packed(store: Path) -> list[bytes | None]:
    """The tiles drawn from the dataset packed whole (no heads involved: the reference)."""
    worker = Worker.of(RenderConfig(store, TileOptions(), 64 << 20, 1000, 50_000))
    assert worker.renderer.pack("hills") is not None
    return drawn(worker)


def jobs() -> list[TileJob | MorphJob]:
    out: list[TileJob | MorphJob] = []
    for z in (12, 13, 14):
        for dx in (-0.02, 0.02):
            _, x, y = tile_for(LON0 + dx, LAT0, z)
            out += [TileJob("hills", z, x, y, z + 0.5, m, None) for m in ("ccsm", "original")]
            out.append(MorphJob("hills", z, x, y))
    return out


def drawn(worker: Worker) -> list[bytes | None]:
    return [run_job(worker, job).body for job in jobs()]


def test_tiles_drawn_with_the_heads_held_are_those_read_per_tile(store: Path) -> None:
    held = Worker.of(config(store))
    per_tile = Worker.of(config(store, head_mb=0))
    assert held.renderer.pack("hills") is None  # the tiles are packed from pieces
    tiles = drawn(held)
    assert sum(t is not None for t in tiles) > 10
    assert tiles == drawn(per_tile) == packed(store)
    heads = held.renderer.heads("hills")
    assert heads is not None and len(heads.heads.fid) == CCSStore(store).dataset("hills").n_contours
    assert per_tile.renderer.heads("hills") is None


def test_heads_beyond_the_head_memory_are_read_per_tile(store: Path) -> None:
    n = CCSStore(store).dataset("hills").n_contours
    worker = Worker.of(config(store, head_mb=n * 8 / (1 << 20)))  # less than a t table per contour
    assert worker.renderer.heads("hills") is None
    assert drawn(worker) == packed(store)


def test_a_rebuilt_dataset_is_drawn_with_its_new_heads(store: Path, tmp_path: Path) -> None:
    worker = Worker.of(config(store))
    old = drawn(worker)
    version = CCSStore(store).data_version("hills")
    other = write_geojson(tmp_path / "hills-2.geojson", synthetic_features(seed=8))
    build_dataset(CCSStore(store), SourceSpec(other, "hills", "hills"), workers=1)
    new = drawn(worker)
    assert new == packed(store) and new != old
    heads = worker.renderer.heads("hills")
    assert heads is not None and heads.data_version == CCSStore(store).data_version("hills") != version


def test_a_worker_on_another_store_file_draws_with_that_stores_heads(tmp_path: Path) -> None:
    # Two fresh stores: the same dataset id, data version and fids, other contours.
    stores = []
    for seed in (3, 8):
        source = write_geojson(tmp_path / f"hills-{seed}.geojson", synthetic_features(seed=seed))
        path = tmp_path / f"store-{seed}.sqlite"
        build_dataset(CCSStore(path), SourceSpec(source, "hills", "hills"), workers=1)
        stores.append(path)
    a, b = (CCSStore(p) for p in stores)
    assert a.data_version("hills") == b.data_version("hills") and a.all_fids("hills")[:5] == b.all_fids("hills")[:5]
    first = drawn(Worker.of(config(stores[0])))
    second = drawn(Worker.of(config(stores[1])))  # in the same process, after the first store's worker
    assert second == packed(stores[1]) and first == packed(stores[0]) and second != first


def test_heads_held_of_an_older_version_give_new_contours_their_stored_heads(store: Path, tmp_path: Path) -> None:
    """A tile that meets the new version's contours before the renderer sees the new version (a rebuild commits
    between its reads) gets their heads from the store, not the old version's at the same positions."""
    old = Worker.of(config(store)).renderer.heads("hills")
    assert old is not None
    other = write_geojson(tmp_path / "hills-2.geojson", synthetic_features(seed=8))
    build_dataset(CCSStore(store), SourceSpec(other, "hills", "hills"), workers=1)
    now = CCSStore(store)
    fids = now.all_fids("hills")
    got = old.of(now, fids)
    assert got.fid.tolist() == fids
    assert np.array_equal(got.tables, np.stack([h.t_at_scale for h in now.load_heads(fids)]))


def test_a_render_worker_reads_its_store_through_the_configured_memory_map(store: Path) -> None:
    worker = Worker.of(replace(config(store), store_mmap_bytes=256 << 20))
    assert worker.renderer.store._con().execute("PRAGMA mmap_size").fetchone()[0] == 256 << 20
    assert drawn(worker) == packed(store)
    plain = Worker.of(config(store))
    assert plain.renderer.store._con().execute("PRAGMA mmap_size").fetchone()[0] == 0
