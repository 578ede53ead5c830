"""Tests of the windowed DEM reader: lines traced window by window are the lines of a whole-grid trace."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio
from synthetic_rasters import fractal_heights, write_geotiff

from engine.errors import InvalidParameter, SourceError
from engine.io.dem import contours_from_dem
from engine.io.dem_windows import contour_windows, join_pieces, window_starts
from engine.types import ContourSet

WEST, NORTH, CELL = 740_000.0, 4_060_000.0, 30.0
#: Vertices of the two traces agree to rounding; a missing or moved vertex is off by a good part of a cell.
SAME_M = 1e-6


def terrain(n: int = 96, seed: int = 5) -> np.ndarray:
    """Rough fractal terrain in whole metres: many small rings and long lines across every window edge."""
    return fractal_heights(seed, 3.0, n=n, relief_m=300.0).astype(np.float32)


def canonical(cs: ContourSet) -> list[tuple[float, bool, np.ndarray]]:
    """Lines as (elevation, closed, coords), rings rotated to start at their lowest vertex, sorted."""
    out = []
    for c in cs.contours:
        coords = c.coords
        if c.closed:
            start = int(np.lexsort((np.round(coords[:, 1], 3), np.round(coords[:, 0], 3)))[0])
            coords = np.roll(coords, -start, axis=0)
        out.append((c.elevation, c.closed, coords))
    return sorted(out, key=lambda e: (e[0], e[1], round(e[2][0, 0], 3), round(e[2][0, 1], 3), len(e[2])))


def assert_same_lines(a: ContourSet, b: ContourSet) -> None:
    ca, cb = canonical(a), canonical(b)
    assert len(ca) == len(cb), f"{len(ca)} lines against {len(cb)}"
    for (ea, closed_a, xa), (eb, closed_b, xb) in zip(ca, cb, strict=True):
        assert (ea, closed_a) == (eb, closed_b)
        assert xa.shape == xb.shape, f"line at {ea} m: {len(xa)} vertices against {len(xb)}"
        assert np.abs(xa - xb).max() < SAME_M, f"line at {ea} m moved by {np.abs(xa - xb).max()} m"


def whole(path: Path, interval: float) -> ContourSet:
    return contours_from_dem(path, interval=interval)  # a small raster is read whole


@pytest.mark.parametrize("block", [5, 16, 37])
def test_windowed_lines_are_the_whole_grid_lines(tmp_path: Path, block: int) -> None:
    path = write_geotiff(tmp_path / "dem.tif", terrain(), west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616")
    reference = whole(path, 10.0)
    windowed = contours_from_dem(path, interval=10.0, block=block)
    assert len(reference.contours) > 300  # enough lines to cross many window edges
    assert_same_lines(windowed, reference)
    assert [b.id.split(":")[0] for b in windowed.bad_features] == [
        b.id.split(":")[0] for b in reference.bad_features
    ]


def test_lines_keep_each_window_edge_vertex_once(tmp_path: Path) -> None:
    """A joined line has no repeated vertex and no vertex more than one cell from the next one."""
    path = write_geotiff(tmp_path / "dem.tif", terrain(), west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616")
    cs = contours_from_dem(path, interval=10.0, block=4)
    for c in cs.contours:
        ring = np.vstack([c.coords, c.coords[:1]]) if c.closed else c.coords
        steps = np.hypot(*np.diff(ring, axis=0).T)
        assert steps.min() > 0, f"{c.id}: repeated vertex"
        assert steps.max() <= CELL * np.sqrt(2) + 1e-6, f"{c.id}: a gap of {steps.max():.1f} m"


def test_nodata_across_window_edges(tmp_path: Path) -> None:
    z = terrain()
    z[20:50, 30:41] = -9999.0  # a hole across several windows: lines end at it on both sides
    path = write_geotiff(
        tmp_path / "dem.tif", z, west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616", nodata=-9999.0
    )
    assert_same_lines(contours_from_dem(path, interval=10.0, block=9), whole(path, 10.0))


def write_tiled(path: Path, z: np.ndarray, driver: str, tile: int) -> Path:
    profile = {
        "driver": driver,
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": z.dtype.name,
        "crs": "EPSG:32616",
        "transform": rasterio.Affine(CELL, 0.0, WEST, 0.0, -CELL, NORTH),
        "blocksize": tile,
    }
    if driver == "GTiff":
        profile.update(tiled=True, blockxsize=tile, blockysize=tile)
        del profile["blocksize"]
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(z, 1)
    return path


@pytest.mark.parametrize("driver", ["GTiff", "COG"])
def test_tiled_and_cloud_optimized_geotiffs(tmp_path: Path, driver: str) -> None:
    path = write_tiled(tmp_path / "tiled.tif", terrain(n=128), driver, tile=16)
    with rasterio.open(path) as src:
        assert src.profile["tiled"] and src.block_shapes[0] == (16, 16)
    reference = whole(path, 10.0)
    for block in (16, 20):  # 20 is rounded up to two internal tiles
        assert_same_lines(contours_from_dem(path, interval=10.0, block=block), reference)


def test_window_starts_share_their_edges() -> None:
    assert window_starts(10, 4) == [0, 4, 8, 9]
    assert window_starts(9, 4) == [0, 4, 8]
    assert window_starts(2, 100) == [0, 1]


def test_join_pieces_of_a_cut_ring_and_a_cut_line() -> None:
    square = [np.array([[0.0, 0.5], [0.5, 0.0], [1.0, 0.0]]), np.array([[1.0, 0.0], [1.5, 0.5], [0.0, 0.5]])]
    line = [np.array([[5.0, 0.0], [5.0, 1.0]]), np.array([[5.0, 1.0], [5.0, 2.0]])]
    joined = join_pieces([line[1], square[0], line[0], square[1]])
    assert len(joined) == 2
    open_line = next(j for j in joined if not np.array_equal(j[0], j[-1]))
    ring = next(j for j in joined if np.array_equal(j[0], j[-1]))
    assert open_line.tolist() == [[5.0, 0.0], [5.0, 1.0], [5.0, 2.0]]
    assert len(ring) == 5 and len(np.unique(ring[:-1], axis=0)) == 4


def test_bad_block_and_flat_dem(tmp_path: Path) -> None:
    path = write_geotiff(tmp_path / "dem.tif", terrain(), west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616")
    with pytest.raises(InvalidParameter, match="block 0"):
        contour_windows(path, 10.0, block=0)
    flat = write_geotiff(
        tmp_path / "flat.tif", np.full((40, 40), 5.0, np.float32), west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616"
    )
    with pytest.raises(SourceError, match="flat.tif: no contour at interval 10"):
        contours_from_dem(flat, interval=10.0, block=8)


def test_large_rasters_are_read_in_windows_without_asking(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import engine.io.dem_windows as dem_windows

    path = write_geotiff(tmp_path / "dem.tif", terrain(), west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616")
    traced: list[object] = []
    real = dem_windows.trace_window

    def spy(*args: object) -> object:
        traced.append(args[1])
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(dem_windows, "trace_window", spy)
    whole(path, 10.0)
    assert traced == []  # 96 x 96 cells: below the threshold, read whole
    monkeypatch.setattr(dem_windows, "WINDOWED_ABOVE_CELLS", 96 * 96 - 1)
    monkeypatch.setattr(dem_windows, "DEFAULT_BLOCK", 32)
    assert_same_lines(whole(path, 10.0), contours_from_dem(path, interval=10.0, block=32))
    assert len(traced) == 9 + 9  # 3 x 3 windows of 32 cells, for each of the two reads
