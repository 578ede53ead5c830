"""``ccsm export`` end to end: a source file and a stored dataset to PMTiles and MBTiles, read back with
sqlite3, the pmtiles package's reader and the pmtiles JS reader (node); bad input exits 2 with a message."""

from __future__ import annotations

import gzip
import json
import re
import sqlite3
import subprocess
from pathlib import Path

import mapbox_vector_tile
import pytest
from pmtiles.reader import MmapSource, Reader, all_tiles
from pmtiles.tile import Compression, TileType
from support.export import fail_render_batch_after
from support.node import NODE_DIR, node_available
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.errors import InvalidParameter
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

_register_commands()
runner = CliRunner()

DATA = Path(__file__).resolve().parents[1] / "data"
MAXZOOM = 13


def run(*args: object):  # type: ignore[no-untyped-def]
    return runner.invoke(app, [str(a) for a in args])


def summary(stdout: str) -> dict[str, int]:
    m = re.search(r": (\d+) tiles \((\w+), gzip MVT, z(\d+)-(\d+); (\d+) empty left out\)", stdout.replace("\n", " "))
    assert m, stdout
    return dict(zip(("tiles", "format", "minzoom", "maxzoom", "empty"), m.groups(), strict=True))  # type: ignore[arg-type]


def morph_tiles(store: Path, dataset: str, minzoom: int, maxzoom: int) -> dict[tuple[int, int, int], bytes]:
    """Every non-empty morph tile of the pyramid, rendered in this process."""
    renderer = Renderer(CCSStore(store, readonly=True))
    info, _ = renderer.info(dataset)
    out = {}
    for z in range(minzoom, maxzoom + 1):  # the grid's own tiles, not the exporter's pyramid
        for t in tiles_covering(Bounds(*info.bounds_3857), z):
            data = renderer.morph_tile(dataset, *t).data
            if data is not None:
                out[tuple(t)] = data
    return out


def layers_and_ids(data: bytes) -> dict[str, list[object]]:
    return {name: [f["id"] for f in layer["features"]] for name, layer in mapbox_vector_tile.decode(data).items()}


@pytest.fixture(scope="module")
def hills_expected(built_store: Path) -> dict[tuple[int, int, int], bytes]:
    return morph_tiles(built_store, "hills", 0, MAXZOOM)


@pytest.fixture(scope="module")
def hills_pmtiles(built_store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pm") / "hills.pmtiles"
    result = run("export", "hills", "--store", built_store, "-o", out, "--maxzoom", MAXZOOM, "--workers", "2")
    assert result.exit_code == 0, result.output
    return out


# -- a source file, built into the cache store --------------------------------------------------------------


def test_export_a_source_to_both_formats_building_it_once(tmp_path: Path) -> None:
    cache = tmp_path / "cache.sqlite"
    src = DATA / "small_contours.geojson"
    pm, mb = tmp_path / "small.pmtiles", tmp_path / "small.mbtiles"
    first = run("export", src, "-o", pm, "--store", cache, "--elevation-field", "ELEV", "--workers", "2")
    assert first.exit_code == 0, first.output
    store = CCSStore(cache, readonly=True)
    (dataset,) = store.dataset_ids()
    built = store.dataset(dataset)
    assert dataset.startswith("src-") and built.n_contours == 5 and built.params["elevation_field"] == "ELEV"
    second = run("export", src, "-o", mb, "--store", cache, "--elevation-field", "ELEV", "--maxzoom", "14")
    assert second.exit_code == 0, second.output
    again = CCSStore(cache, readonly=True).dataset(dataset)
    assert (again.data_version, again.built_at) == (built.data_version, built.built_at)  # not rebuilt
    expected = morph_tiles(cache, dataset, 0, 14)
    for out, result in ((pm, first), (mb, second)):
        counts = summary(result.stdout)
        assert int(counts["tiles"]) == len(expected) and int(counts["empty"]) > 0
        assert out.is_file()
    with sqlite3.connect(mb) as con:
        assert con.execute("SELECT COUNT(*) FROM tiles").fetchone()[0] == len(expected)
    with open(pm, "rb") as f:
        assert sum(1 for _ in all_tiles(MmapSource(f))) == len(expected)
    # Other build options are another source: built again, as another dataset.
    third = run("export", src, "-o", pm, "--store", cache, "--elevation-field", "ELEV", "--target-scale", "1e6")
    assert third.exit_code == 0, third.output
    assert len(CCSStore(cache, readonly=True).dataset_ids()) == 2


# -- a stored dataset ---------------------------------------------------------------------------------------


def test_export_a_dataset_to_mbtiles_read_with_sqlite3(built_store: Path, tmp_path: Path, hills_expected: dict) -> None:
    out = tmp_path / "hills.mbtiles"
    result = run("export", "--store", built_store, "--dataset", "hills", "-o", out, "--maxzoom", MAXZOOM)
    assert result.exit_code == 0, result.output
    with sqlite3.connect(out) as con:
        meta = dict(con.execute("SELECT name, value FROM metadata").fetchall())
        rows = con.execute("SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles").fetchall()
    assert meta["format"] == "pbf" and meta["name"] == "hills"
    assert (meta["minzoom"], meta["maxzoom"]) == ("0", str(MAXZOOM))
    assert len(meta["bounds"].split(",")) == 4 and len(meta["center"].split(",")) == 3
    doc = json.loads(meta["json"])
    assert [v["id"] for v in doc["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert doc["ccsm_morph"]["start_layer"] == "contours" and doc["ccsm_morph"]["end_layer"] == "contours_end"
    assert len(rows) == len(hills_expected) == int(summary(result.stdout)["tiles"])
    tiles = {(z, x, (1 << z) - 1 - row): data for z, x, row, data in rows}  # TMS -> XYZ
    assert tiles.keys() == hills_expected.keys()
    key = max(hills_expected, key=lambda k: (len(hills_expected[k]), k))
    got = gzip.decompress(tiles[key])
    want = layers_and_ids(hills_expected[key])
    assert layers_and_ids(got) == want and {"contours", "contours_end"} <= set(want) and want["contours"]
    assert mapbox_vector_tile.decode(got) == mapbox_vector_tile.decode(hills_expected[key])


def test_export_a_dataset_to_pmtiles_read_with_the_python_reader(hills_pmtiles: Path, hills_expected: dict) -> None:
    with open(hills_pmtiles, "rb") as f:
        reader = Reader(MmapSource(f))
        header, meta = reader.header(), reader.metadata()
        tiles = {tuple(zxy): bytes(data) for zxy, data in all_tiles(MmapSource(f))}
    assert header["tile_type"] == TileType.MVT and header["tile_compression"] == Compression.GZIP
    assert (header["min_zoom"], header["max_zoom"]) == (0, MAXZOOM)
    assert header["min_lon_e7"] < header["center_lon_e7"] < header["max_lon_e7"]
    assert header["min_lat_e7"] < header["center_lat_e7"] < header["max_lat_e7"]
    assert [v["id"] for v in meta["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert meta["ccsm_morph"]["version"] == 1
    assert tiles.keys() == hills_expected.keys()
    key = max(hills_expected, key=lambda k: (len(hills_expected[k]), k))
    assert layers_and_ids(gzip.decompress(tiles[key])) == layers_and_ids(hills_expected[key])


def test_export_pmtiles_read_with_the_js_reader(hills_pmtiles: Path, hills_expected: dict) -> None:
    """The pmtiles JS reader (what MapLibre's pmtiles protocol uses) reads the header and decodes tiles."""
    if not node_available("pmtiles"):
        pytest.fail("node and tests/app/node/node_modules are required: run `make install` (npm ci in tests/app/node)")
    keys = sorted(hills_expected, key=lambda k: (-len(hills_expected[k]), k))[:3]
    args = [f"{z}/{x}/{y}" for z, x, y in keys]
    out = subprocess.run(
        ["node", str(NODE_DIR / "read_pmtiles.mjs"), str(hills_pmtiles), *args, f"{MAXZOOM}/0/0"],
        capture_output=True,
        text=True,
        check=True,
    )
    doc = json.loads(out.stdout)
    header = doc["header"]
    assert header["specVersion"] == 3 and header["tileType"] == 1 and header["tileCompression"] == 2
    assert (header["minZoom"], header["maxZoom"]) == (0, MAXZOOM)
    assert header["numAddressedTiles"] == len(hills_expected)
    assert [v["id"] for v in doc["metadata"]["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    for key, tile in zip(keys, doc["tiles"], strict=False):
        want = layers_and_ids(hills_expected[key])
        assert tile["layers"][:2] == ["contours", "contours_end"]
        assert {name: d["ids"] for name, d in tile["detail"].items()} == want
        assert tile["detail"]["contours"]["extent"] == 4096
    assert doc["tiles"][-1] == {"tile": f"{MAXZOOM}/0/0", "missing": True}


# -- bad input ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nope", "--store", "{store}", "-o", "{tmp}/x.pmtiles"], "nope: no such file, nor a dataset of"),
        (["--dataset", "nope", "--store", "{store}", "-o", "{tmp}/x.pmtiles"], "nor a dataset of"),
        (["hills", "--store", "{tmp}/none.sqlite", "-o", "{tmp}/x.pmtiles"], "no store at"),
        (["hills", "--store", "{store}", "-o", "{tmp}/x.pmtiles", "--minzoom", "9", "--maxzoom", "8"], "greater than"),
        (["hills", "--store", "{store}", "-o", "{tmp}/x.pmtiles", "--maxzoom", "20"], "--maxzoom must be <= 16"),
        (["hills", "--store", "{store}", "-o", "{tmp}/x.zip"], "unknown archive extension '.zip'"),
        (["hills", "--store", "{store}", "-o", "{tmp}/afile/x.mbtiles"], "cannot write"),
        (["hills", "--store", "{store}", "-o", "{tmp}/adir.pmtiles"], "is a directory"),
        (["hills", "--store", "{store}", "-o", "{tmp}/x.pmtiles", "--workers", "0"], "--workers must be >= 1"),
        (["{src}", "--store", "{tmp}/c.sqlite", "-o", "{tmp}/x.pmtiles", "--source-scale", "0"], "--source-scale"),
        (["{src}", "--store", "{tmp}/afile/c.sqlite", "-o", "{tmp}/x.pmtiles"], "cannot open the store"),
        (["--store", "{store}", "-o", "{tmp}/x.pmtiles"], "give a contour file or DEM"),
        (["{src}", "--dataset", "hills", "--store", "{store}", "-o", "{tmp}/x.pmtiles"], "not both"),
    ],
)
def test_bad_input_exits_2_with_a_message(
    built_store: Path, synthetic_path: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    (tmp_path / "afile").write_text("")
    (tmp_path / "adir.pmtiles").mkdir()
    argv = [
        a.replace("{store}", str(built_store)).replace("{tmp}", str(tmp_path)).replace("{src}", str(synthetic_path))
        for a in args
    ]
    result = run("export", *argv)
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.stderr.split()), result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 or "\n" not in result.stderr.strip()
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir.pmtiles", "afile"]  # nothing written


@pytest.mark.parametrize("suffix", [".pmtiles", ".mbtiles"])
def test_a_failed_export_keeps_the_existing_file(
    built_store: Path, tmp_path: Path, suffix: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / f"hills{suffix}"
    out.write_bytes(b"yesterday's archive")
    bad = run("export", "hills", "--store", built_store, "-o", out, "--minzoom", "5", "--maxzoom", "4")
    assert bad.exit_code == 2 and out.read_bytes() == b"yesterday's archive"
    calls = fail_render_batch_after(monkeypatch, 1, InvalidParameter("the renderer gave up"))
    result = run("export", "hills", "--store", built_store, "-o", out, "--workers", "1", "--maxzoom", "12")
    assert result.exit_code == 2, result.output
    assert "the renderer gave up" in result.stderr and len(calls) == 2
    assert out.read_bytes() == b"yesterday's archive"
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]
