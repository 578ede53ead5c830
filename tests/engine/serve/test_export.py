"""The static export (engine.serve.export, engine.tiles.archives): the pyramid, and both archives read back by
readers that share no code with the writers (stdlib sqlite3 for MBTiles, the pmtiles package's reader)."""

from __future__ import annotations

import gzip
import json
import sqlite3
from pathlib import Path

import mapbox_vector_tile
import pytest
from pmtiles.reader import MmapSource, Reader, all_tiles
from pmtiles.tile import Compression, TileType, zxy_to_tileid
from support.export import fail_render_batch_after

import engine.serve.export as export_mod
from engine.build.datasets import SourceSpec, build_dataset
from engine.errors import InvalidParameter, StoreError, UnknownLayer
from engine.serve.export import check_zoom_range, export_dataset, pyramid
from engine.serve.renderer import Renderer
from engine.store.records import DatasetInfo
from engine.store.store import CCSStore
from engine.tiles.archives import ArchiveMeta, open_archive
from engine.tiles.grid import mercator_to_lonlat, tiles_covering
from engine.types import Bounds

DATA = Path(__file__).resolve().parents[2] / "data"
DATASET = "small"
MINZOOM, MAXZOOM = 0, 14


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tests/data/small_contours.geojson (5 good contours, 5 defects) built into a store as 'small'."""
    path = tmp_path_factory.mktemp("store") / "small.sqlite"
    spec = SourceSpec(DATA / "small_contours.geojson", DATASET, "small contours", elevation_field="ELEV")
    build_dataset(CCSStore(path), spec, workers=1)
    return path


@pytest.fixture(scope="module")
def info(store: Path) -> DatasetInfo:
    return CCSStore(store, readonly=True).dataset(DATASET)


@pytest.fixture(scope="module")
def expected(store: Path, info: DatasetInfo) -> dict[tuple[int, int, int], bytes]:
    """Every non-empty morph tile of the pyramid, rendered here, uncompressed."""
    renderer = Renderer(CCSStore(store, readonly=True))
    out = {}
    for z in range(MINZOOM, MAXZOOM + 1):
        for t in tiles_covering(Bounds(*info.bounds_3857), z):
            data = renderer.morph_tile(DATASET, *t).data
            if data is not None:
                out[tuple(t)] = data
    return out


@pytest.fixture(scope="module")
def mbtiles(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("mb") / "small.mbtiles"
    export_dataset(store, DATASET, out, minzoom=MINZOOM, maxzoom=MAXZOOM, workers=2, batch_size=3)
    return out


@pytest.fixture(scope="module")
def pmtiles_path(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pm") / "small.pmtiles"
    export_dataset(store, DATASET, out, minzoom=MINZOOM, maxzoom=MAXZOOM, workers=2, batch_size=3)
    return out


def decoded(data: bytes) -> dict[str, list[tuple[object, dict, object]]]:
    """Layers of an MVT decoded by mapbox_vector_tile: per layer, (id, properties, geometry) of each feature."""
    tile = mapbox_vector_tile.decode(data)
    return {
        name: [(f["id"], f["properties"], f["geometry"]) for f in layer["features"]] for name, layer in tile.items()
    }


def lonlat_bounds(info: DatasetInfo) -> list[float]:
    minx, miny, maxx, maxy = info.bounds_3857
    lon, lat = mercator_to_lonlat([minx, maxx], [miny, maxy])  # type: ignore[arg-type]
    return [float(lon[0]), float(lat[0]), float(lon[1]), float(lat[1])]


# -- the pyramid -------------------------------------------------------------------------------------------


def test_pyramid_is_every_tile_of_every_zoom_in_tile_id_order(info: DatasetInfo) -> None:
    tiles = pyramid(info.bounds_3857, 3, 12)
    for z in range(3, 13):
        assert {t for t in tiles if t.z == z} == set(tiles_covering(Bounds(*info.bounds_3857), z))
    assert len(tiles) == len(set(tiles)) == sum(len(tiles_covering(Bounds(*info.bounds_3857), z)) for z in range(3, 13))
    ids = [zxy_to_tileid(*t) for t in tiles]
    assert ids == sorted(ids)


def test_the_test_set_has_empty_and_non_empty_tiles_at_every_zoom(expected: dict, info: DatasetInfo) -> None:
    # The archive tests below compare against these tiles: they must cover every zoom and leave some out.
    assert {z for z, _, _ in expected} == set(range(MINZOOM, MAXZOOM + 1))
    assert len(expected) < len(pyramid(info.bounds_3857, MINZOOM, MAXZOOM))
    assert all({"contours", "contours_end"} <= set(decoded(d)) <= {"contours", "contours_end", "contour_labels"}
               for d in expected.values())


# -- MBTiles, read with sqlite3 ----------------------------------------------------------------------------


def test_mbtiles_metadata(mbtiles: Path, info: DatasetInfo) -> None:
    with sqlite3.connect(mbtiles) as con:
        meta = dict(con.execute("SELECT name, value FROM metadata").fetchall())
    assert meta["name"] == "small contours"
    assert meta["format"] == "pbf"
    assert (int(meta["minzoom"]), int(meta["maxzoom"])) == (MINZOOM, MAXZOOM)
    assert [float(v) for v in meta["bounds"].split(",")] == pytest.approx(lonlat_bounds(info), abs=1e-6)
    lon, lat, zoom = (float(v) for v in meta["center"].split(","))
    west, south, east, north = lonlat_bounds(info)
    assert west <= lon <= east and south <= lat <= north and MINZOOM <= zoom <= MAXZOOM
    doc = json.loads(meta["json"])
    assert [layer["id"] for layer in doc["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert {"elevation", "index", "t", "t8", "min_zoom"} <= set(doc["vector_layers"][0]["fields"])
    assert doc["ccsm_morph"] == {"version": 1, "t_samples": 8, "start_layer": "contours", "end_layer": "contours_end"}


def test_mbtiles_holds_every_non_empty_tile_gzip_under_its_tms_row(mbtiles: Path, expected: dict) -> None:
    with sqlite3.connect(mbtiles) as con:
        rows = con.execute("SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles").fetchall()
    assert len(rows) == len(expected)
    got = {}
    for z, x, row, data in rows:
        assert data[:2] == b"\x1f\x8b"  # gzip
        got[(z, x, (1 << z) - 1 - row)] = gzip.decompress(data)
    assert got.keys() == expected.keys()
    for key, data in got.items():
        assert data == expected[key], key
    # One tile decoded by a second MVT decoder: the same layers, feature ids, properties and geometry.
    key = max(expected, key=lambda k: (len(expected[k]), k))
    want = decoded(expected[key])
    assert decoded(got[key]) == want and want["contours"]
    assert [f[0] for f in decoded(got[key])["contours_end"]] == [f[0] for f in want["contours"]]


# -- PMTiles, read with the pmtiles package's reader -------------------------------------------------------


def test_pmtiles_header_and_metadata(pmtiles_path: Path, info: DatasetInfo, expected: dict) -> None:
    with open(pmtiles_path, "rb") as f:
        reader = Reader(MmapSource(f))
        header = reader.header()
        meta = reader.metadata()
    assert header["tile_type"] == TileType.MVT
    assert header["tile_compression"] == Compression.GZIP
    assert (header["min_zoom"], header["max_zoom"]) == (MINZOOM, MAXZOOM)
    assert header["clustered"]
    assert header["addressed_tiles_count"] == len(expected)
    west, south, east, north = lonlat_bounds(info)
    e7 = [header["min_lon_e7"], header["min_lat_e7"], header["max_lon_e7"], header["max_lat_e7"]]
    assert [v / 1e7 for v in e7] == pytest.approx([west, south, east, north], abs=2e-7)
    assert west <= header["center_lon_e7"] / 1e7 <= east and south <= header["center_lat_e7"] / 1e7 <= north
    assert MINZOOM <= header["center_zoom"] <= MAXZOOM
    assert meta["name"] == "small contours" and meta["attribution"]
    assert [layer["id"] for layer in meta["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert meta["ccsm_morph"]["t_samples"] == 8 and meta["ccsm_morph"]["version"] == 1


def test_pmtiles_holds_every_non_empty_tile_gzip(pmtiles_path: Path, expected: dict) -> None:
    with open(pmtiles_path, "rb") as f:
        source = MmapSource(f)
        tiles = {tuple(zxy): bytes(data) for zxy, data in all_tiles(source)}
        key = max(expected, key=lambda k: (len(expected[k]), k))
        one = Reader(source).get(*key)
        missing = [k for k in expected if Reader(source).get(*k) is None]
    assert not missing
    assert tiles.keys() == expected.keys()
    for k, data in tiles.items():
        assert data[:2] == b"\x1f\x8b", k
        assert gzip.decompress(data) == expected[k], k
    assert one is not None and decoded(gzip.decompress(one)) == decoded(expected[key])


def test_workers_do_not_change_the_archive(store: Path, pmtiles_path: Path, tmp_path: Path) -> None:
    one = tmp_path / "one.pmtiles"
    export_dataset(store, DATASET, one, minzoom=MINZOOM, maxzoom=MAXZOOM, workers=1)
    assert one.read_bytes() == pmtiles_path.read_bytes()


def test_zoom_range_is_exported_exactly(store: Path, tmp_path: Path, expected: dict) -> None:
    out = tmp_path / "part.mbtiles"
    result = export_dataset(store, DATASET, out, minzoom=9, maxzoom=11, workers=2)
    with sqlite3.connect(out) as con:
        zooms = sorted(z for (z,) in con.execute("SELECT DISTINCT zoom_level FROM tiles"))
        count = con.execute("SELECT COUNT(*) FROM tiles").fetchone()[0]
    assert zooms == [9, 10, 11]
    assert count == result.tiles == sum(1 for z, _, _ in expected if 9 <= z <= 11)


# -- failures ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".pmtiles", ".mbtiles"])
def test_a_failed_export_leaves_the_existing_file_and_no_temporary(
    store: Path, tmp_path: Path, suffix: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / f"old{suffix}"
    out.write_bytes(b"the previous archive")
    calls = fail_render_batch_after(monkeypatch, 2, RuntimeError("disk on fire"))
    with pytest.raises(RuntimeError, match="disk on fire"):
        export_dataset(store, DATASET, out, workers=1, batch_size=2)
    assert len(calls) == 3  # it failed half way, after tiles were written to the temporary file
    assert out.read_bytes() == b"the previous archive"
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]


@pytest.mark.parametrize("suffix", [".pmtiles", ".mbtiles"])
def test_an_archive_given_no_tile_is_refused_and_leaves_no_file(tmp_path: Path, suffix: str) -> None:
    archive = open_archive(tmp_path / f"none{suffix}")
    meta = ArchiveMeta("none", 0, 4, (7.0, 46.0, 8.0, 47.0), (7.5, 46.5, 2), [])
    with pytest.raises(InvalidParameter, match="every tile is empty"):
        archive.commit(meta)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("minzoom", "maxzoom", "message"),
    [(5, 4, "greater than --maxzoom"), (-1, 4, "--minzoom must be >= 0"), (0, 17, "--maxzoom must be <= 16")],
)
def test_bad_zoom_range(minzoom: int, maxzoom: int, message: str) -> None:
    with pytest.raises(InvalidParameter, match=message):
        check_zoom_range(minzoom, maxzoom)


def test_bad_target_and_dataset(store: Path, tmp_path: Path) -> None:
    with pytest.raises(InvalidParameter, match="unknown archive extension '.zip'"):
        export_dataset(store, DATASET, tmp_path / "x.zip")
    with pytest.raises(UnknownLayer):
        export_dataset(store, "nope", tmp_path / "x.pmtiles")
    (tmp_path / "file").write_text("")
    with pytest.raises(InvalidParameter, match="cannot write"):
        export_dataset(store, DATASET, tmp_path / "file" / "x.mbtiles")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_header_states_the_exported_zoom_range_when_its_ends_are_empty(
    store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Tiles exist only at z3..z12 here (the others rendered empty): the header, like the MBTiles metadata, still
    # states the range exported, not just the zooms that happen to hold tiles.
    real = export_mod.render_batch

    def middle_only(renderer, dataset, tiles):  # type: ignore[no-untyped-def]
        return [t for t in real(renderer, dataset, tiles) if 3 <= t[0] <= 12]

    monkeypatch.setattr(export_mod, "render_batch", middle_only)
    out = tmp_path / "middle.pmtiles"
    export_dataset(store, DATASET, out, minzoom=1, maxzoom=14, workers=1)
    with open(out, "rb") as f:
        source = MmapSource(f)
        header = Reader(source).header()
        zooms = {zxy[0] for zxy, _ in all_tiles(source)}
    assert zooms == set(range(3, 13))
    assert (header["min_zoom"], header["max_zoom"]) == (1, 14)


def test_a_dataset_rebuilt_during_the_export_fails_it(
    store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    copy = tmp_path / "copy.sqlite"
    CCSStore(store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    copy.write_bytes(store.read_bytes())
    real = export_mod.render_batch

    def rebuild_after_first(*args, **kwargs):  # type: ignore[no-untyped-def]
        with sqlite3.connect(copy) as con:  # what a concurrent `ccsm build --force` does to the row
            con.execute("UPDATE datasets SET data_version = data_version + 1 WHERE id = ?", (DATASET,))
        return real(*args, **kwargs)

    monkeypatch.setattr(export_mod, "render_batch", rebuild_after_first)
    out = tmp_path / "x.pmtiles"
    with pytest.raises(StoreError, match="changed during the export"):
        export_dataset(copy, DATASET, out, workers=1, batch_size=4)
    assert not out.exists()
