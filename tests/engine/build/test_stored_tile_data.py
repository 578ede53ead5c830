"""What the build stores so that no tile request recomputes it: the target rows' significance and the label
anchors; and the tiles of a dataset too large for the renderer's contour memory (packed per tile) are the
tiles of the same dataset packed whole."""

import sqlite3
from pathlib import Path

import numpy as np
import pytest

import engine.build.labels as build_labels
from engine.build.datasets import SourceSpec, build_dataset
from engine.cartography.dataset import dataset_cartography, label_sources
from engine.cartography.labels import place_labels
from engine.errors import StoreError
from engine.intervals import infer_interval
from engine.io.source import sample_contours_path
from engine.serve.heads import DatasetHeads
from engine.serve.pack import HeadColumns
from engine.serve.renderer import Renderer
from engine.store.schema import MIGRATIONS, STORE_FORMAT
from engine.store.store import CCSStore, pieces_sql
from engine.tiles.grid import Tile, buffered, tile_bounds, tiles_covering
from engine.tiles.significance import row_significance
from engine.types import Bounds


@pytest.fixture(scope="module")
def sample_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("stored") / "sample.sqlite"
    build_dataset(CCSStore(path), SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    return path


def test_stored_target_significance_is_the_target_rows_own(sample_store: Path) -> None:
    store = CCSStore(sample_store, readonly=True)
    recs = store.load(store.all_fids("sample"))
    differs = 0
    for r in recs:
        assert r.sig_top.dtype == np.float32 and len(r.sig_top) == len(r.top)
        assert np.array_equal(r.sig_top, row_significance(r.top))
        differs += int(not np.array_equal(r.sig_top, r.sig))
    assert differs > len(recs) // 2  # the target's own significance, not that of (base, top) together


def placed_by_hand(store: CCSStore, dataset: str, last_zoom: float):  # noqa: ANN201 - LabelAnchors
    """The labels as the renderer placed them on a tile request before the build stored them."""
    info = store.dataset(dataset)
    elevations = store.elevations(dataset)
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    sources = label_sources(carto, store.load(store.all_fids(dataset)))
    upright = place_labels(sources, info.ladder, carto.latitude, last_zoom)
    assert carto.options.label_orientation == "uphill" and carto.uphill_side is None  # a contour file's labels
    return build_labels.uphill_from_neighbours(store, dataset, upright)


def test_stored_labels_are_those_placed_from_the_stored_contours(sample_store: Path) -> None:
    store = CCSStore(sample_store, readonly=True)
    stored = store.labels("sample")
    assert stored is not None and stored.data_version == store.data_version("sample")
    placed = stored.anchors
    expected = placed_by_hand(store, "sample", Renderer(store).options.max_zoom + 1.0)
    assert len(expected) > 100
    assert np.array_equal(placed.fid, expected.fid)
    assert np.array_equal(placed.xy, expected.xy)
    assert np.array_equal(placed.angle, expected.angle)
    assert np.array_equal(placed.min_zoom, expected.min_zoom)
    assert np.array_equal(placed.rank, expected.rank)
    assert np.array_equal(placed.elevation, expected.elevation)
    assert np.array_equal(placed.box_px, expected.box_px)
    assert placed.text == expected.text


def count_placements(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Every placement of a dataset's labels, counted: the walk among the candidates that each one ends in,
    whether their candidates were found here or by workers reading the store."""
    import engine.cartography.labels as cartography_labels

    calls: list[int] = []
    real = cartography_labels.place_among

    def counted(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(cartography_labels, "place_among", counted)
    monkeypatch.setattr(build_labels, "place_among", counted)
    return calls


def tile_with_labels(renderer: Renderer, store: CCSStore, dataset: str) -> tuple[int, int, int]:
    """A z14 tile of the dataset whose label layer is not empty."""
    labels = store.labels(dataset)
    assert labels is not None and len(labels.anchors)
    for z, x, y in tiles_covering(Bounds(*store.dataset(dataset).bounds_3857), 14):
        data = renderer.tile(dataset, z, x, y).data
        if data is not None and b"contour_labels" in data:
            return z, x, y
    raise AssertionError("no tile with labels")


def test_placing_labels_reads_the_rows_of_the_labelled_contours_only(
    sample_store: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = CCSStore(sample_store, readonly=True)
    every = store.load(store.all_fids("sample"))
    info, elevations = store.dataset("sample"), store.elevations("sample")
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    labelled = [src.fid for src in label_sources(carto, every)]
    loaded: list[int] = []
    real_load = CCSStore.load

    def recorded_load(self: CCSStore, fids: list[int]) -> list:
        loaded.extend(fids)
        return real_load(self, fids)

    monkeypatch.setattr(CCSStore, "load", recorded_load)
    monkeypatch.setattr(build_labels, "uphill_from_neighbours", lambda store, dataset, anchors: anchors)
    placed = build_labels.place_dataset_labels(store, "sample", 16)
    assert loaded == labelled and len(labelled) < len(every) / 3
    assert set(placed.anchors.fid.tolist()) <= set(labelled)


def test_first_tile_after_a_build_places_no_labels(
    tmp_path: Path, sample_store: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = count_placements(monkeypatch)
    store = CCSStore(tmp_path / "fresh.sqlite")
    build_dataset(store, SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    assert len(calls) == 1  # the build placed them
    z, x, y = tile_with_labels(Renderer(CCSStore(sample_store, readonly=True)), store, "sample")
    renderer = Renderer(store)
    first = renderer.tile("sample", z, x, y)
    assert first.data is not None and b"contour_labels" in first.data
    assert len(calls) == 1  # ... and the first tile of a new renderer only read them


def test_a_version_stored_without_labels_has_them_placed_on_the_first_tile(
    tmp_path: Path, sample_store: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = CCSStore(sample_store, readonly=True)
    z, x, y = tile_with_labels(Renderer(store), store, "sample")
    expected = Renderer(store).tile("sample", z, x, y).data
    CCSStore(tmp_path / "bare.sqlite").close()
    con = sqlite3.connect(tmp_path / "bare.sqlite")  # the rows as they are, no labels: a build that placed none
    con.execute("ATTACH DATABASE ? AS src", (str(sample_store),))
    for table in ("contours", "contour_rtree", "datasets"):
        con.execute(f"INSERT INTO {table} SELECT * FROM src.{table}")
    con.commit()
    con.close()
    bare = CCSStore(tmp_path / "bare.sqlite")
    fids = store.all_fids("sample")
    assert bare.labels("sample") is None and bare.all_fids("sample") == fids
    calls = count_placements(monkeypatch)
    assert Renderer(bare).tile("sample", z, x, y).data == expected
    assert len(calls) == 1


def test_a_store_of_a_format_no_migration_reaches_is_refused_by_name(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    CCSStore(path).close()
    older = min(MIGRATIONS) - 1
    con = sqlite3.connect(path)
    con.execute("UPDATE store_meta SET value=? WHERE key='format'", (str(older),))
    con.commit()
    con.close()
    with pytest.raises(StoreError, match=f"has format {older}, expected {STORE_FORMAT}"):
        CCSStore(path)


def sample_tiles(store: CCSStore) -> list[tuple[int, int, int]]:
    bounds = Bounds(*store.dataset("sample").bounds_3857)
    return [tuple(t) for z in (11, 13, 14) for t in tiles_covering(bounds, z)[::5]]  # type: ignore[misc]


def test_the_compared_tiles_read_pieces_with_gaps_and_contours_with_no_piece(sample_store: Path) -> None:
    """The tiles the next tests compare join pieces across gaps and stand in for contours without a piece."""
    store = CCSStore(sample_store, readonly=True)
    gaps = stand_ins = multi = 0
    for kind in ("ccs", "original"):
        for z, x, y in sample_tiles(store):
            box = buffered(tile_bounds(Tile(z, x, y)), 64, 4096)
            pieces = store.pieces_meeting("sample", box, kind)
            same = pieces.fid[1:] == pieces.fid[:-1]
            gaps += int((same & (pieces.k[1:] != pieces.k[:-1] + 1)).sum())
            multi += int((same & (pieces.k[1:] == pieces.k[:-1] + 1)).sum())
            stand_ins += len(set(store.query("sample", box)) - set(pieces.fid.tolist()))
    assert gaps > 0 and multi > 0 and stand_ins > 0


@pytest.mark.parametrize("method", ["ccsm", "original", "dp"])
def test_tiles_of_a_dataset_larger_than_the_contour_memory_equal_the_packed_tiles(
    sample_store: Path, method: str
) -> None:
    store = CCSStore(sample_store, readonly=True)
    packed = Renderer(store)
    per_tile = Renderer(store, contour_cache_bytes=1 << 20)
    assert packed.pack("sample") is not None and per_tile.pack("sample") is None
    tiles = sample_tiles(store)
    assert len(tiles) > 20
    drawn = 0
    for z, x, y in tiles:
        for zoom in (float(z), z + 0.5):
            a = packed.tile("sample", z, x, y, zoom=zoom, method=method).data
            b = per_tile.tile("sample", z, x, y, zoom=zoom, method=method).data
            assert a == b, (method, z, x, y, zoom)
            drawn += a is not None
    assert drawn > 20


def test_morph_tiles_of_a_dataset_larger_than_the_contour_memory_equal_the_packed_ones(sample_store: Path) -> None:
    store = CCSStore(sample_store, readonly=True)
    packed = Renderer(store)
    per_tile = Renderer(store, contour_cache_bytes=1 << 20)
    drawn = 0
    for z, x, y in sample_tiles(store):
        a = packed.morph_tile("sample", z, x, y).data
        assert a == per_tile.morph_tile("sample", z, x, y).data, (z, x, y)
        drawn += a is not None
    assert drawn > 20


@pytest.fixture(scope="module")
def twice_sample_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample stored twice: every piece of one dataset lies where the other's do."""
    path = tmp_path_factory.mktemp("stored") / "twice.sqlite"
    store = CCSStore(path)
    for ident in ("sample", "again"):
        build_dataset(store, SourceSpec(sample_contours_path(), ident, ident), workers=2)
    return path


def test_a_tile_of_stored_pieces_leaves_out_the_pieces_of_another_dataset_in_the_same_place(
    twice_sample_store: Path,
) -> None:
    store = CCSStore(twice_sample_store, readonly=True)
    packed = Renderer(store)
    per_tile = Renderer(store, contour_cache_bytes=1 << 20)
    assert per_tile.pack("again") is None
    heads = per_tile.heads("again")
    assert heads is not None and heads.fid_range is not None  # the pieces are told apart by their fids
    drawn = 0
    for z, x, y in sample_tiles(store):
        box = buffered(tile_bounds(Tile(z, x, y)), 64, 4096)
        by_range = store.pieces_meeting("again", box, "ccs", heads.fid_range)
        by_dataset = store.pieces_meeting("again", box, "ccs")
        assert np.array_equal(by_range.fid, by_dataset.fid) and np.array_equal(by_range.k, by_dataset.k)
        for method in ("ccsm", "original"):
            a = packed.tile("again", z, x, y, method=method).data
            assert a == per_tile.tile("again", z, x, y, method=method).data, (method, z, x, y)
            drawn += a is not None
    assert drawn > 20


def test_the_fids_of_a_dataset_with_a_gap_are_no_range() -> None:
    def heads(fid: list[int]) -> DatasetHeads:
        n = len(fid)
        return DatasetHeads(1, HeadColumns(np.array(fid, np.int64), np.zeros(n), np.zeros(n), np.zeros((n, 2))))

    assert heads([4, 5, 6]).fid_range == (4, 6)
    assert heads([4, 6, 7]).fid_range is None
    assert heads([]).fid_range is None


@pytest.mark.parametrize("by_fid", [True, False])
@pytest.mark.parametrize("kind", ["ccs", "original"])
def test_the_pieces_query_searches_the_rtree_first(sample_store: Path, kind: str, by_fid: bool) -> None:
    """Walking the pieces' fid index first reads every piece of the dataset: 200 ms a tile at 64× the sample."""
    con = sqlite3.connect(f"file:{sample_store}?mode=ro", uri=True)
    plan = con.execute(f"EXPLAIN QUERY PLAN {pieces_sql(kind, by_fid)}", (0.0, 1.0, 0.0, 1.0, 1, 2)[: 6 - (not by_fid)])
    steps = [row[3] for row in plan.fetchall()]
    con.close()
    assert steps[0].startswith("SCAN r VIRTUAL TABLE") and "PRIMARY KEY" in steps[1], steps
