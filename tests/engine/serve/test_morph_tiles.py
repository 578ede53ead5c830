"""Morph tiles (docs/morph-tiles.md): a client that interpolates one tile per level, as the document says,
draws what the service's own fractional-zoom tiles draw, within one tile unit in each coordinate.

The client side is written here from the document, independently of the server code, on the bundled sample
and on a generated terrain the engine was not tuned on.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from support.mvt import decode, decode_served
from synthetic_rasters import fractal_heights, write_geotiff

from engine.build.datasets import SourceSpec, build_dataset
from engine.io.source import sample_contours_path
from engine.serve.renderer import Renderer, TileOptions
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

pytestmark = pytest.mark.slow

EXTENT = 4096
#: Tile units beyond the tile's edge that one side of a comparison is clipped at (well inside the buffer).
MARGIN = 4.0
#: One tile unit in each coordinate: the two ends of the level and the served slice are each rounded to the grid.
TOLERANCE = math.sqrt(2.0)
FRACTIONS = (0.0, 0.37, 0.81)  # the level's start, and between the eighths where t is sampled


def parts_of(geometry: dict) -> list[np.ndarray]:
    if geometry["type"] == "LineString":
        return [np.asarray(geometry["coordinates"], dtype=float)]
    return [np.asarray(p, dtype=float) for p in geometry["coordinates"]]


def t_at(props: dict, f: float) -> float:
    """The document's piecewise-linear t through the level from its nine samples."""
    samples = [props["t"]] + [props[f"t{k}"] for k in range(1, 9)]
    s = 8 * f
    k = min(int(math.floor(s)), 7)
    return samples[k] + (s - k) * (samples[k + 1] - samples[k])


def interpolate(morph: dict, f: float, zoom: float) -> dict[int, list[np.ndarray]]:
    """Every contour drawn at zoom z + f, by feature id, as the document's client draws it."""
    ends = {feat["id"]: feat for feat in morph["contours_end"]["features"]}
    out = {}
    for feat in morph["contours"]["features"]:
        props = feat["properties"]
        if zoom <= props["min_zoom"]:
            continue
        t0, t8 = props["t"], props["t8"]
        w = 0.0 if t8 == t0 else (t_at(props, f) - t0) / (t8 - t0)
        starts, finals = parts_of(feat["geometry"]), parts_of(ends[feat["id"]]["geometry"])
        out[feat["id"]] = [a + w * (b - a) for a, b in zip(starts, finals, strict=True)]
    return out


def in_tile(parts: list[np.ndarray], margin: float = 0.0, extent: int = EXTENT) -> shapely.Geometry:
    lines = shapely.multilinestrings([shapely.linestrings(p) for p in parts if len(p) >= 2])
    return shapely.clip_by_rect(lines, -margin, -margin, extent + margin, extent + margin)


def farthest(a: shapely.Geometry, b: shapely.Geometry, step: float = 2.0) -> float:
    """How far any point of ``a`` lies from ``b`` (the directed Hausdorff distance, sampled every ``step``)."""
    points = shapely.points(shapely.get_coordinates(shapely.segmentize(a, step)))
    return float(shapely.distance(points, b).max()) if len(points) else 0.0


def apart(a: list[np.ndarray], b: list[np.ndarray], extent: int = EXTENT) -> float:
    """How far two drawings of a contour are apart inside the tile. Each side inside the tile is compared with
    the other clipped a little wider, so a line running along the tile's edge is not cut differently."""
    wide, step = MARGIN * extent / EXTENT, 2.0 * extent / EXTENT
    return max(
        farthest(in_tile(a, 0, extent), in_tile(b, wide, extent), step),
        farthest(in_tile(b, 0, extent), in_tile(a, wide, extent), step),
    )


def held_still(morph: dict) -> set[int]:
    """Contours whose level generalizes them (t changes) but whose two layers are the same shape: held."""
    ends = {feat["id"]: parts_of(feat["geometry"]) for feat in morph["contours_end"]["features"]}
    return {
        feat["id"]
        for feat in morph["contours"]["features"]
        if feat["properties"]["t"] != feat["properties"]["t8"]
        and all(np.array_equal(a, b) for a, b in zip(parts_of(feat["geometry"]), ends[feat["id"]], strict=True))
    }


def served_lines_at(renderer: Renderer, dataset: str, z: int, x: int, y: int, zoom: float) -> dict:
    served_tile = renderer.tile(dataset, z, x, y, zoom=zoom).data
    served = decode_served(served_tile)
    return {feat["id"]: parts_of(feat["geometry"]) for feat in served.get("contours", {}).get("features", [])}


def compare_level(renderer: Renderer, dataset: str, z: int, x: int, y: int) -> tuple[float, int, int]:
    """(worst Hausdorff distance in tile units, contours compared, of which held) over the level's fractions.
    A held contour is compared with the served slice at the level's end, the shape it is held at."""
    result = renderer.morph_tile(dataset, z, x, y)
    if result.data is None:
        return 0.0, 0, 0
    morph = decode(result.data)
    extent = renderer.options.extent
    held = held_still(morph)
    at_end = served_lines_at(renderer, dataset, z, x, y, z + 1.0 - 1e-9) if held else {}
    worst, compared, compared_held = 0.0, 0, 0
    for f in FRACTIONS:
        zoom = z + f
        served_lines = served_lines_at(renderer, dataset, z, x, y, zoom)
        drawn = interpolate(morph, f, zoom)
        for fid, parts in served_lines.items():
            want = in_tile(parts, 0, extent)
            if want.is_empty:
                continue
            assert fid in drawn, f"contour {fid} is served at zoom {zoom} but the morph tile does not draw it"
            worst = max(worst, apart(drawn[fid], at_end[fid] if fid in held else parts, extent))
            compared += 1
            compared_held += fid in held
        for fid, parts in drawn.items():
            got = in_tile(parts, 0, extent)
            # A contour the morph draws inside the tile must be served too (a sliver along the edge aside).
            if not got.is_empty and got.length > 2 * extent / EXTENT:
                assert fid in served_lines, f"the morph tile draws contour {fid} at zoom {zoom}; the service does not"
    return worst, compared, compared_held


def tiles_near_centre(info_bounds: tuple[float, float, float, float], z: int, n: int = 3) -> list[tuple[int, int, int]]:
    tiles = tiles_covering(Bounds(*info_bounds), z)
    mid = len(tiles) // 2
    return [tuple(t) for t in tiles[max(0, mid - n // 2) : mid - n // 2 + n]]  # type: ignore[misc]


@pytest.fixture(scope="module")
def sample_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("morph") / "sample.sqlite"
    build_dataset(CCSStore(path), SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    return path


@pytest.fixture(scope="module")
def terrain_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("morph-terrain")
    dem = write_geotiff(
        folder / "alps.tif",
        fractal_heights(seed=5, beta=2.7, n=128).astype("float32"),
        west=400_000.0,
        north=5_150_000.0,
        cell=30.0,
        crs="EPSG:32632",
    )
    path = folder / "terrain.sqlite"
    spec = SourceSpec(dem, "terrain", "terrain", interval=10.0, source_scale=25_000.0, target_scale=250_000.0)
    build_dataset(CCSStore(path), spec, workers=2)
    return path


@pytest.mark.parametrize("which", ["sample", "terrain"])
def test_interpolated_morph_tiles_equal_the_served_slices(which: str, sample_store: Path, terrain_store: Path) -> None:
    store = CCSStore(sample_store if which == "sample" else terrain_store)
    renderer = Renderer(store)
    info = store.dataset(which)
    worst, compared, held = 0.0, 0, 0
    for z in range(9, 15):
        for tile in tiles_near_centre(info.bounds_3857, z, 2):
            w, n, h = compare_level(renderer, which, *tile)
            worst, compared, held = max(worst, w), compared + n, held + h
    assert compared > 500  # many contours, tiles, zooms and fractions were really compared
    print(f"{which}: {compared} contours compared, {held} of them still through their level")
    assert worst <= TOLERANCE, f"interpolated geometry is {worst:.2f} tile units from the served slice"


def test_both_layers_have_the_same_vertices(sample_store: Path) -> None:
    store = CCSStore(sample_store)
    renderer = Renderer(store)
    info = store.dataset("sample")
    checked = 0
    for z in (9, 12):
        for tile in tiles_near_centre(info.bounds_3857, z):
            data = renderer.morph_tile("sample", *tile).data
            assert data is not None
            morph = decode(data)
            start = {f["id"]: parts_of(f["geometry"]) for f in morph["contours"]["features"]}
            end = {f["id"]: parts_of(f["geometry"]) for f in morph["contours_end"]["features"]}
            assert start.keys() == end.keys()
            for fid, parts in start.items():
                assert [len(p) for p in parts] == [len(p) for p in end[fid]]
                checked += 1
    assert checked > 100


def test_a_level_that_generalizes_moves_its_vertices(sample_store: Path) -> None:
    # Around 1:200,000 the sample's contours are between the source and the target: the two layers differ.
    store = CCSStore(sample_store)
    info = store.dataset("sample")
    morph = decode(Renderer(store).morph_tile("sample", *tiles_near_centre(info.bounds_3857, 10, 1)[0]).data)
    moved = 0
    ends = {f["id"]: parts_of(f["geometry"]) for f in morph["contours_end"]["features"]}
    for feat in morph["contours"]["features"]:
        props = feat["properties"]
        assert 0.0 <= props["t8"] <= props["t"] <= 1.0  # t falls as the zoom rises
        if props["t"] > props["t8"] and any(
            (a != b).any() for a, b in zip(parts_of(feat["geometry"]), ends[feat["id"]], strict=True)
        ):
            moved += 1
    assert moved > 10


def test_on_a_sixteen_times_finer_grid_the_morph_still_matches(sample_store: Path) -> None:
    # On the sample a vertex moves by about two units of a 4096 grid through a level, so a client that
    # interpolated towards the wrong end (t7 instead of t8) would still pass above. On a 65536 grid the same
    # mistake is four units off; the right geometry stays within one unit per coordinate.
    store = CCSStore(sample_store)
    renderer = Renderer(store, TileOptions(extent=16 * EXTENT, buffer_px=16 * 64))
    info = store.dataset("sample")
    worst, compared = 0.0, 0
    for z in (10, 11):
        w, n, _held = compare_level(renderer, "sample", *tiles_near_centre(info.bounds_3857, z, 1)[0])
        worst, compared = max(worst, w), compared + n
    assert compared > 300
    assert worst <= TOLERANCE, f"interpolated geometry is {worst:.2f} fine-grid units from the served slice"
