"""Terrain tile pyramids and GeoTIFFs over HTTP as a user meets them: made from real DEMs (Maunga Whau, Howe
Sound), served by a real HTTP server on loopback, read through the same windowed reader as a GeoTIFF."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import rasterio
from hypothesis import given, settings
from hypothesis import strategies as st
from range_server import serve_folder
from real_dems import MAUNGA_WHAU_ASC, TOPOBATHY_WINDOW, topobathy
from shapely.geometry import MultiLineString
from terrain_pyramids import Pyramid, write_cog, write_pyramid

from engine.errors import InvalidParameter, SourceError
from engine.io.dem import contours_from_dem, read_dem
from engine.io.raster_windows import RasterDem
from engine.io.source import parse_source
from engine.io.terrain_tiles import ENCODINGS, TerrainTiles, TileEncoding, default_zoom
from engine.types import ContourSet

MAPBOX, TERRARIUM = ENCODINGS["mapbox"], ENCODINGS["terrarium"]


def maunga_whau() -> tuple[np.ndarray, rasterio.Affine, str]:
    grid = read_dem(MAUNGA_WHAU_ASC)
    return grid.z.filled(np.nan), rasterio.Affine(*grid.transform), "EPSG:2193"


def howe_sound() -> tuple[np.ndarray, rasterio.Affine, str]:
    """The window of topobathy.npz (heights and depths, whole metres) on its regular lon/lat grid, north up."""
    z, lon, lat = topobathy()
    z, lon, lat = z[TOPOBATHY_WINDOW], lon[TOPOBATHY_WINDOW[1]], lat[TOPOBATHY_WINDOW[0]]
    dx, dy = (lon[-1] - lon[0]) / (len(lon) - 1), (lat[-1] - lat[0]) / (len(lat) - 1)
    transform = rasterio.Affine(dx, 0, lon[0] - dx / 2, 0, -dy, lat[-1] + dy / 2)
    return z[::-1], transform, "EPSG:4326"


def by_level(cs: ContourSet) -> dict[float, MultiLineString]:
    lines: dict[float, list[np.ndarray]] = defaultdict(list)
    for c in cs.contours:
        lines[c.elevation].append(np.vstack([c.coords, c.coords[:1]]) if c.closed else c.coords)
    return {level: MultiLineString([line.tolist() for line in ls]) for level, ls in lines.items()}


def assert_same_contours(a: ContourSet, b: ContourSet, tolerance_m: float) -> None:
    """The same levels, and each level's lines within ``tolerance_m`` (Hausdorff) of the other's."""
    la, lb = by_level(a), by_level(b)
    assert sorted(la) == sorted(lb)
    worst = max(la[level].hausdorff_distance(lb[level]) for level in la)
    assert worst <= tolerance_m, f"a level's lines lie {worst:.3f} m apart"


def tiles_of(pyramid: Pyramid, url: str, encoding: TileEncoding) -> TerrainTiles:
    return TerrainTiles(encoding, url + "/{z}/{x}/{y}.png", pyramid.bbox, pyramid.zoom)


@pytest.mark.parametrize(
    ("dem", "zoom", "encoding", "interval"),
    [(maunga_whau, 16, MAPBOX, 10.0), (maunga_whau, 16, TERRARIUM, 10.0), (howe_sound, 10, TERRARIUM, 200.0),
     (howe_sound, 10, MAPBOX, 200.0)],
)
def test_a_served_pyramid_gives_the_contours_of_its_geotiff(
    tmp_path: Path, dem: object, zoom: int, encoding: TileEncoding, interval: float
) -> None:
    z, transform, crs = dem()  # type: ignore[operator]
    pyramid = write_pyramid(tmp_path, z, transform, crs, zoom=zoom, encoding=encoding)
    assert len(pyramid.tiles) >= 4  # lines cross tile edges
    # Windows of 100 cells for both: lines are joined across windows as well as across tiles.
    from_geotiff = contours_from_dem(RasterDem(str(pyramid.geotiff), pyramid.bbox), interval=interval, block=100)
    with serve_folder(pyramid.root) as server:
        from_tiles = contours_from_dem(tiles_of(pyramid, server.url, encoding), interval=interval, block=100)
        assert server.count(".png") >= len(pyramid.tiles)
    # The GeoTIFF's heights lie on the encoding's steps: the tiles hold them exactly, so the lines agree to
    # rounding.
    assert from_tiles.working_crs == from_geotiff.working_crs
    assert len(from_tiles.contours) == len(from_geotiff.contours)
    assert_same_contours(from_tiles, from_geotiff, 1e-6)


def test_heights_between_steps_move_lines_by_less_than_a_pixel(tmp_path: Path) -> None:
    z, transform, crs = maunga_whau()
    pyramid = write_pyramid(tmp_path, z, transform, crs, zoom=16, encoding=MAPBOX, on_step=False)
    from_geotiff = contours_from_dem(RasterDem(str(pyramid.geotiff), pyramid.bbox), interval=10.0)
    with serve_folder(pyramid.root) as server:
        from_tiles = contours_from_dem(tiles_of(pyramid, server.url, MAPBOX), interval=10.0)
    # Rounding to 0.1 m moves a line by at most 0.05 m / slope: a few centimetres on the cone, metres only where
    # the ground is nearly flat at a level (the crater floor). Nearly every vertex stays within a tenth of a
    # 1.9 m pixel, none farther than 5 pixels.
    import shapely

    la, lb = by_level(from_tiles), by_level(from_geotiff)
    assert sorted(la) == sorted(lb)
    far = np.concatenate(
        [shapely.distance(shapely.points(shapely.get_coordinates(la[level])), lb[level]) for level in la]
    )
    print("vertex distances (m): median", np.median(far), "95 %", np.quantile(far, 0.95), "max", far.max())
    assert np.median(far) < 0.1 and far.max() < 10.0


def test_folder_template_pmtiles_and_mbtiles_give_the_same_contours(tmp_path: Path) -> None:
    import sqlite3

    from pmtiles.tile import Compression, TileType, zxy_to_tileid
    from pmtiles.writer import Writer

    z, transform, crs = maunga_whau()
    pyramid = write_pyramid(tmp_path, z, transform, crs, zoom=16, encoding=TERRARIUM)
    via_folder = contours_from_dem(TerrainTiles(TERRARIUM, f"file://{pyramid.root}/{{z}}/{{x}}/{{y}}.png",
                                                pyramid.bbox, 16), interval=10.0)
    pm_path, mb_path = tmp_path / "t.pmtiles", tmp_path / "t.mbtiles"
    with open(pm_path, "wb") as fh:
        writer = Writer(fh)
        for tz, tx, ty in sorted(pyramid.tiles, key=lambda t: zxy_to_tileid(*t)):
            writer.write_tile(zxy_to_tileid(tz, tx, ty), (pyramid.root / f"{tz}/{tx}/{ty}.png").read_bytes())
        writer.finalize(
            {"tile_type": TileType.PNG, "tile_compression": Compression.NONE, "min_zoom": 16, "max_zoom": 16,
             "min_lon_e7": 0, "min_lat_e7": 0, "max_lon_e7": 0, "max_lat_e7": 0, "center_zoom": 16,
             "center_lon_e7": 0, "center_lat_e7": 0},
            {},
        )
    con = sqlite3.connect(mb_path)
    con.execute("CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB)")
    for tz, tx, ty in pyramid.tiles:
        data = (pyramid.root / f"{tz}/{tx}/{ty}.png").read_bytes()
        con.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (tz, tx, (1 << tz) - 1 - ty, data))
    con.commit()
    con.close()
    for archive in (pm_path, mb_path):
        got = contours_from_dem(TerrainTiles(TERRARIUM, str(archive), pyramid.bbox, 16), interval=10.0)
        assert_same_contours(got, via_folder, 1e-9)
    with serve_folder(tmp_path) as server:  # a PMTiles archive over HTTP, by range requests
        got = contours_from_dem(TerrainTiles(TERRARIUM, server.url + "/t.pmtiles", pyramid.bbox, 16), interval=10.0)
        assert_same_contours(got, via_folder, 1e-9)
        assert server.bytes_for(".pmtiles") > 0


def test_a_served_cog_is_read_by_ranges_and_gives_the_local_contours(tmp_path: Path) -> None:
    # Howe Sound's whole topobathy grid, resampled 12x finer (1092 x 1440 cells) so that it has many internal tiles.
    z, lon, lat = topobathy()
    fine = np.kron(z[::-1], np.ones((12, 12)))
    dx, dy = (lon[-1] - lon[0]) / (len(lon) - 1) / 12, (lat[-1] - lat[0]) / (len(lat) - 1) / 12
    transform = rasterio.Affine(dx, 0, lon[0], 0, -dy, lat[-1])
    cog = write_cog(tmp_path / "topobathy.tif", fine, transform, "EPSG:4326")
    size = cog.stat().st_size
    bbox = (-123.3, 49.3, -122.9, 49.6)  # Howe Sound: about a fifteenth of the grid
    local = contours_from_dem(RasterDem(str(cog), bbox), interval=100.0)
    with serve_folder(tmp_path) as server:
        remote_source = parse_source(server.url + "/topobathy.tif", bbox=bbox)
        assert isinstance(remote_source, RasterDem)
        remote = contours_from_dem(remote_source, interval=100.0)
        served = server.bytes_for("topobathy.tif")
        assert server.count() == server.count("topobathy.tif")  # no folder listing, no sidecar files asked for
    assert served < 0.5 * size, f"{served} of {size} bytes read"
    assert len(remote.contours) == len(local.contours) > 10
    assert_same_contours(remote, local, 1e-9)


def make_maunga_whau_pyramid(tmp_path: Path) -> Pyramid:
    z, transform, crs = maunga_whau()
    return write_pyramid(tmp_path, z, transform, crs, zoom=16, encoding=MAPBOX)


def test_a_missing_tile_a_tile_that_is_no_image_and_a_refused_connection_name_the_tile(tmp_path: Path) -> None:
    pyramid = make_maunga_whau_pyramid(tmp_path)
    zoom, x, y = pyramid.tiles[-1]
    tile = pyramid.root / f"{zoom}/{x}/{y}.png"
    with serve_folder(pyramid.root) as server:
        source = tiles_of(pyramid, server.url, MAPBOX)
        tile.unlink()
        with pytest.raises(SourceError, match=rf"tile {zoom}/{x}/{y} \({server.url}/{zoom}/{x}/{y}.png\): HTTP 404"):
            contours_from_dem(source, interval=10.0)
        tile.write_text("<html>not a tile</html>")
        with pytest.raises(SourceError, match=rf"tile {zoom}/{x}/{y} \(.*/{zoom}/{x}/{y}.png\): not an image"):
            contours_from_dem(tiles_of(pyramid, server.url, MAPBOX), interval=10.0)
    refused = TerrainTiles(MAPBOX, "http://127.0.0.1:9/{z}/{x}/{y}.png", pyramid.bbox, 16)
    first = pyramid.tiles[0]
    named = rf"tile {first[0]}/{first[1]}/{first[2]} \(http://127.0.0.1:9/.*cannot fetch"
    with pytest.raises(SourceError, match=named):
        contours_from_dem(refused, interval=10.0)
    with pytest.raises(SourceError, match="http://127.0.0.1:9/dem.tif: cannot read DEM"):
        contours_from_dem(RasterDem("http://127.0.0.1:9/dem.tif"), interval=10.0)


def test_an_area_without_tiles_and_a_wrong_encoding_are_named(tmp_path: Path) -> None:
    pyramid = make_maunga_whau_pyramid(tmp_path)
    with serve_folder(pyramid.root) as server:
        elsewhere = TerrainTiles(MAPBOX, server.url + "/{z}/{x}/{y}.png", (10.0, 45.0, 10.01, 45.01), 16)
        with pytest.raises(SourceError, match=r"tile 16/\d+/\d+ \(http.*HTTP 404.*does the pyramid cover it"):
            contours_from_dem(elsewhere, interval=10.0)
        with pytest.raises(SourceError, match="unknown terrain tile encoding 'terrain'; expected terrarium, mapbox"):
            parse_source(f"terrain:{server.url}/{{z}}/{{x}}/{{y}}.png", bbox=pyramid.bbox)
    with pytest.raises(InvalidParameter, match="needs an area"):
        parse_source("mapbox:/tiles/{z}/{x}/{y}.png")
    with pytest.raises(SourceError, match="custom:BASE:SCALE:LOCATION"):
        parse_source("custom:0.1:/tiles/{z}/{x}/{y}.png", bbox=pyramid.bbox)
    custom = parse_source("custom:-10000:0.1:/t/{z}/{x}/{y}.png", bbox=pyramid.bbox, dem_zoom=15)
    assert isinstance(custom, TerrainTiles) and custom.encoding.base == -10000 and custom.zoom == 15


def test_the_default_zoom_matches_the_source_scale() -> None:
    # 1:50,000 shows 0.28 mm as 14 m: z13 at 36.9 S (15.3 m pixels), z12 at 60 N (19.1 m beats z13's 9.6 m).
    assert default_zoom(50_000, (174.7, -36.9, 174.8, -36.8)) == 13
    assert default_zoom(50_000, (10.0, 59.9, 10.1, 60.1)) == 12
    assert default_zoom(25_000, (174.7, -36.9, 174.8, -36.8)) == 14


@settings(max_examples=200, deadline=None)
@given(
    heights=st.lists(st.floats(-10_000.0, 8_848.0, allow_nan=False), min_size=1, max_size=64),
    name=st.sampled_from(["mapbox", "terrarium"]),
)
def test_decoding_an_encoded_height_is_within_half_a_step(heights: list[float], name: str) -> None:
    encoding = ENCODINGS[name]
    h = np.asarray(heights).reshape(1, -1)
    back = encoding.decode(encoding.encode(h))
    assert np.all(np.abs(back - h) <= encoding.scale / 2 + 1e-9)


def test_the_decoders_follow_the_published_formulas() -> None:
    # Mapbox terrain-RGB: -10000 + (R*65536 + G*256 + B) * 0.1; Terrarium: R*256 + G + B/256 - 32768.
    rgb = np.array([[[1, 134, 160], [1, 134, 170], [128, 0, 0], [128, 100, 128], [0, 0, 0]]], dtype=np.uint8)
    assert MAPBOX.decode(rgb)[0, :2].round(9).tolist() == [0.0, 1.0]
    assert TERRARIUM.decode(rgb)[0, 2:].tolist() == [0.0, 100.5, -32768.0]
    assert MAPBOX.decode(rgb)[0, 4] == -10000.0


@pytest.mark.parametrize("kind", ["pyramid", "cog"])
def test_remote_dems_store_their_uphill_side_and_their_labels_face_uphill(tmp_path: Path, kind: str) -> None:
    """A served tile pyramid and a served COG (north up) keep higher ground on the traced lines' right; the
    build stores that, and each label's top faces higher ground on the DEM the tiles were cut from."""
    from scipy import ndimage

    from engine.build.datasets import SourceSpec, build_dataset
    from engine.cartography.labels import UPSIDE_DOWN_LIMIT_DEG
    from engine.cartography.neighbour_uphill import text_top
    from engine.cartography.options import CartographyOptions
    from engine.store.store import CCSStore

    pyramid = make_maunga_whau_pyramid(tmp_path)  # its GeoTIFF is the tiles' Web Mercator grid
    if kind == "cog":
        (tmp_path / "root").mkdir()
        with rasterio.open(pyramid.geotiff) as src:
            write_cog(tmp_path / "root" / "mw.tif", src.read(1), src.transform, "EPSG:3857")
    root = pyramid.root if kind == "pyramid" else tmp_path / "root"
    store = CCSStore(tmp_path / "s.sqlite")
    with serve_folder(root) as server:
        source = tiles_of(pyramid, server.url, MAPBOX) if kind == "pyramid" else RasterDem(server.url + "/mw.tif")
        spec = SourceSpec(source, "mw", "mw", interval=5.0, source_scale=5_000.0, target_scale=50_000.0,
                          cartography=CartographyOptions(index_every=2))
        build_dataset(store, spec, workers=1)
    assert store.dataset("mw").params["uphill_side"] == "right"
    stored = store.labels("mw")
    assert stored is not None and len(stored.anchors.xy) >= 10
    a = stored.anchors
    with rasterio.open(pyramid.geotiff) as src:
        z, inverse = src.read(1).astype(np.float64), ~src.transform
    step = text_top(a.angle) * 2.0
    (c0, r0), (c1, r1) = (inverse * tuple((a.xy + s).T) for s in (step, -step))
    top = ndimage.map_coordinates(z, [np.asarray(r0) - 0.5, np.asarray(c0) - 0.5], order=1, mode="nearest")
    foot = ndimage.map_coordinates(z, [np.asarray(r1) - 0.5, np.asarray(c1) - 0.5], order=1, mode="nearest")
    told = np.isfinite(top - foot) & (np.abs(top - foot) > 0.05)
    wrong = told & (top < foot)
    assert (np.abs(a.angle[wrong]) <= 180.0 - UPSIDE_DOWN_LIMIT_DEG + 1e-6).all(), a.angle[wrong]
    assert (np.abs(a.angle) > 90.0).sum() >= 3


def test_windows_and_the_whole_grid_agree_on_lines_at_the_node_snap_threshold(tmp_path: Path) -> None:
    """Heights in terrain-RGB's 0.1 m steps put a level's node artefacts exactly NODE_SNAP_PX (0.01 px) from
    their nodes: two short lines of Maunga Whau's Web Mercator grid, by the nodata edge. Whole and in windows,
    the same lines are kept and the same reported."""
    pyramid = make_maunga_whau_pyramid(tmp_path)
    whole = contours_from_dem(pyramid.geotiff, interval=10.0)
    for block in (100, 37):
        windowed = contours_from_dem(RasterDem(str(pyramid.geotiff)), interval=10.0, block=block)
        assert len(windowed.contours) == len(whole.contours)
        assert sorted(b.id for b in windowed.bad_features) == sorted(b.id for b in whole.bad_features)
        assert_same_contours(windowed, whole, 1e-6)
    assert len(whole.bad_features) == 2  # both artefacts of the 100 m level, reported
