"""Issue 10: a render worker decides a morph tile's crossing check once per data version and tile.

The crossing check (engine/tiles/morph_untangle.py) is the slow part of a morph tile, and its answer depends
only on the dataset's data version and the tile, so a morph worker keeps the tiles it drew
(``CCSM_MORPH_CACHE_MB``, app/render/jobs.py). Here a worker state on a real store draws the same tile twice
(one check), then the dataset is rebuilt with other contours (a new data version): the tile is checked and
drawn again, and it is the new data's tile.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import engine.serve.morph_tiles as morph_module
from app.render.jobs import MorphJob, RenderConfig, Worker, run_job
from engine.build.datasets import SourceSpec, build_dataset
from engine.serve.renderer import TileOptions
from engine.store.store import CCSStore
from tests.app.conftest import LAT0, LON0, synthetic_features, write_geojson
from tests.app.helpers import tile_for


@pytest.fixture()
def checks(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the morph crossing checks the renderer runs (one entry per check of a tile)."""
    calls: list[int] = []
    check = morph_module.untangle

    def counted(*args, **kwargs):
        calls.append(1)
        return check(*args, **kwargs)

    monkeypatch.setattr(morph_module, "untangle", counted)
    return calls


def config(store: Path, cache_mb: int = 8) -> RenderConfig:
    return RenderConfig(store, TileOptions(), 64 << 20, 1000, 50_000, morph_cache_bytes=cache_mb << 20)


def hills_morph_job(z: int = 12) -> MorphJob:
    _, x, y = tile_for(LON0, LAT0, z)
    return MorphJob("hills", z, x, y)


def test_a_second_identical_morph_request_does_not_redo_the_check(store, checks):
    worker = Worker.of(config(store))
    first = run_job(worker, hills_morph_job())
    assert first.body and len(checks) == 1
    again = run_job(worker, hills_morph_job())
    assert again.body == first.body and len(checks) == 1
    # Another tile is its own entry: checked once too.
    other = run_job(worker, hills_morph_job(13))
    assert other.body and other.body != first.body and len(checks) == 2
    run_job(worker, hills_morph_job(13))
    assert len(checks) == 2


def test_a_new_data_version_is_checked_and_drawn_again(store, checks, tmp_path):
    worker = Worker.of(config(store))
    old = run_job(worker, hills_morph_job())
    assert len(checks) == 1
    # The dataset is rebuilt from other contours (another seed of the same hills): a new data version.
    version = CCSStore(store).data_version("hills")
    other = write_geojson(tmp_path / "hills-2.geojson", synthetic_features(seed=8))
    build_dataset(CCSStore(store), SourceSpec(other, "hills", "hills"), workers=1)
    assert CCSStore(store).data_version("hills") != version
    new = run_job(worker, hills_morph_job())
    assert len(checks) == 2
    fresh = run_job(Worker.of(config(store)), hills_morph_job())  # a worker that never saw the old version
    assert new.body == fresh.body and new.body != old.body


def test_no_cache_when_its_size_is_zero(store, checks):
    worker = Worker.of(config(store, cache_mb=0))
    run_job(worker, hills_morph_job())
    run_job(worker, hills_morph_job())
    assert len(checks) == 2 and len(worker.morph_tiles) == 0
