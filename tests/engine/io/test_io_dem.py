"""Tests of contouring DEMs: GeoTIFF, ESRI ASCII grid and the .npz layout of matplotlib's sample DEM."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from synthetic_rasters import write_geotiff

from engine.errors import InvalidParameter, SourceError
from engine.io.crs import make_transformer
from engine.io.dem import read_dem
from engine.io.dem_tracing import LEVEL_OFFSET, contour_levels
from engine.io.source import contours_from_dem, read_source

DATA = Path(__file__).resolve().parents[2] / "data"

#: Upper-left corner of the synthetic UTM 16N grids, metres.
WEST, NORTH = 740_000.0, 4_060_000.0
PIXEL_M = 100.0


def cone(
    rows: int, cols: int, peak_rc: tuple[float, float], top: float = 500.0, slope: float = 40.0
) -> np.ndarray:
    """Heights of a cone: ``top`` at pixel (row, col) ``peak_rc``, falling ``slope`` per pixel."""
    r, c = np.mgrid[0:rows, 0:cols]
    return top - slope * np.hypot(r - peak_rc[0], c - peak_rc[1])


def write_tif(
    path: Path,
    z: np.ndarray,
    *,
    crs: str | None = "EPSG:32616",
    nodata: float | None = None,
    north_up: bool = True,
) -> Path:
    return write_geotiff(path, z, west=WEST, north=NORTH, cell=PIXEL_M, crs=crs, nodata=nodata, north_up=north_up)


def write_npz(
    path: Path, z: np.ndarray, *, xmin: float, xmax: float, ymin: float, ymax: float, d: float
) -> Path:
    np.savez(path, elevation=z, xmin=xmin, xmax=xmax, ymin=ymin, ymax=ymax, dx=d, dy=d)
    return path


def centroid(coords: np.ndarray) -> np.ndarray:
    return coords.mean(axis=0)


# ------------------------------------------------------------------------------------- GeoTIFF
def test_geotiff_cone(tmp_path: Path) -> None:
    z = cone(30, 40, peak_rc=(10, 25)).astype(np.float32)
    cs = read_source(write_tif(tmp_path / "cone.tif", z), interval=50)
    assert cs.name == "cone"
    assert cs.source_crs == cs.working_crs == "EPSG:32616"
    assert cs.interval == 50.0
    top = max(cs.contours, key=lambda c: c.elevation)
    assert top.elevation == 450.0
    assert top.closed
    assert top.id == "450:0"
    # Pixel centres: column 25 is at x = WEST + 25.5 px, row 10 at y = NORTH - 10.5 px.
    assert_allclose(centroid(top.coords), [WEST + 25.5 * PIXEL_M, NORTH - 10.5 * PIXEL_M], atol=2.0)
    radius = np.hypot(*(top.coords - centroid(top.coords)).T)
    # Linear interpolation along grid edges cuts the cone's circle short between the edges.
    assert_allclose(radius, (500 - 450 - LEVEL_OFFSET) / 40 * PIXEL_M, rtol=0.08)
    zmin = float(z.min())
    expected_levels = {float(v) for v in range(-5000, 500, 50) if v >= zmin}
    assert {c.elevation for c in cs.contours} == expected_levels
    assert all(not np.array_equal(c.coords[0], c.coords[-1]) for c in cs.contours if c.closed)


def test_geotiff_south_up_rows(tmp_path: Path) -> None:
    # Same heights, but row 0 is the southern edge: the peak must land near the south.
    z = cone(30, 40, peak_rc=(5, 25)).astype(np.float32)
    cs = read_source(write_tif(tmp_path / "south_up.tif", z, north_up=False), interval=50)
    top = max(cs.contours, key=lambda c: c.elevation)
    south = NORTH - 30 * PIXEL_M
    assert_allclose(centroid(top.coords), [WEST + 25.5 * PIXEL_M, south + 5.5 * PIXEL_M], atol=2.0)


def test_geotiff_nodata_is_not_contoured(tmp_path: Path) -> None:
    z = cone(30, 40, peak_rc=(15, 20)).astype(np.float32)
    z[:, :10] = -9999.0
    cs = read_source(write_tif(tmp_path / "hole.tif", z, nodata=-9999.0), interval=50)
    assert min(c.elevation for c in cs.contours) > -9999
    west_edge = WEST + 10 * PIXEL_M
    assert min(c.coords[:, 0].min() for c in cs.contours) >= west_edge - 1e-6


def test_geotiff_without_crs(tmp_path: Path) -> None:
    path = write_tif(tmp_path / "nocrs.tif", cone(10, 10, (5, 5)).astype(np.float32), crs=None)
    with pytest.raises(SourceError, match="nocrs.tif: the DEM has no CRS"):
        read_source(path, interval=50)


def test_geographic_geotiff_is_projected_to_utm(tmp_path: Path) -> None:
    z = cone(20, 20, (10, 10)).astype(np.float32)
    path = write_geotiff(tmp_path / "geo.tif", z, west=-84.3, north=36.7, cell=0.001, crs="EPSG:4326")
    cs = read_source(path, interval=50)
    assert cs.source_crs == "EPSG:4326"
    assert cs.working_crs == "EPSG:32616"
    top = max(cs.contours, key=lambda c: c.elevation)
    assert 700_000 < top.coords[0, 0] < 800_000  # metres, not degrees


# --------------------------------------------------------------- whole metres and the level offset
def test_whole_metre_heights_give_clean_lines(tmp_path: Path) -> None:
    z = np.round(cone(30, 40, peak_rc=(12.3, 20.7), slope=20.0)).astype(np.int16)
    cs = read_source(write_tif(tmp_path / "int.tif", z), interval=20)
    for c in cs.contours:
        steps = np.hypot(*np.diff(c.coords, axis=0).T)
        assert steps.min() >= 1e-3
    assert not any("zero length" in b.reason for b in cs.bad_features)


def test_nodes_exactly_at_the_level(tmp_path: Path) -> None:
    # A pit at 10 whose rim touches the northern edge at a node exactly at 20.
    z = np.array(
        [
            [30, 30, 20, 30, 30],
            [30, 30, 10, 30, 30],
            [30, 30, 30, 30, 30],
            [30, 30, 30, 30, 30],
        ],
        dtype=np.int16,
    )
    cs = read_source(write_tif(tmp_path / "pit.tif", z), interval=10)
    # The 20 m line circles the pit and starts and ends a ten-thousandth of a pixel either side of the node at
    # exactly 20 m: a ring touching the edge, not an open line.
    (line20,) = cs.contours
    assert line20.elevation == 20.0
    assert line20.closed
    # At 10 m the pit bottom itself is the contour: a point, traced 1 mm higher as a ring of a few
    # millimetres. It is reported, not kept.
    (bad,) = cs.bad_features
    assert bad.id == "10:0"
    assert bad.reason.startswith("degenerate contour: grid nodes lie exactly at 10")
    assert bad.where == "pit.tif"


def test_ids_are_stable(tmp_path: Path) -> None:
    path = write_tif(tmp_path / "c.tif", cone(30, 40, (10, 25)).astype(np.float32))
    first = contours_from_dem(path, interval=25)
    second = contours_from_dem(path, interval=25)
    assert [c.id for c in first.contours] == [c.id for c in second.contours]
    assert all(c.id == f"{c.elevation:g}:{str(c.id).split(':')[1]}" for c in first.contours)
    assert len({c.id for c in first.contours}) == len(first.contours)


def test_contour_levels() -> None:
    assert contour_levels(236, 1076, 20).tolist() == list(range(240, 1061, 20))
    assert contour_levels(0.0, 1.0, 0.1).tolist()[:4] == [0.0, 0.1, 0.2, 0.3]
    assert contour_levels(-25, 25, 10).tolist() == [-20, -10, 0, 10, 20]


# ----------------------------------------------------------------------------------- .asc
def test_ascii_grid_fixture() -> None:
    cs = read_source(DATA / "cone_utm16n.asc", interval=20)
    assert cs.source_crs == cs.working_crs == "EPSG:32616"
    top = max(cs.contours, key=lambda c: c.elevation)
    assert top.elevation == 480.0 and top.closed
    # Peak at row 3, column 7 of a 10-row grid whose lower-left corner is (700000, 4060000).
    assert_allclose(centroid(top.coords), [700_000 + 7.5 * 100, 4_060_000 + (10 - 3.5) * 100], atol=5.0)


def test_ascii_grid_without_prj(tmp_path: Path) -> None:
    shutil.copy(DATA / "cone_utm16n.asc", tmp_path / "cone.asc")
    with pytest.raises(SourceError, match=r"cone.asc: the DEM has no CRS \(is the .prj file missing\?\)"):
        read_source(tmp_path / "cone.asc", interval=20)


# ------------------------------------------------------------------------------------- .npz
def test_npz_row_zero_is_north(tmp_path: Path) -> None:
    # matplotlib's layout: ymin holds the northern edge. Peak in row 5 (north) of 40, column 30 (east) of 40.
    d = 0.001
    z = cone(40, 40, peak_rc=(5, 30))
    path = write_npz(
        tmp_path / "north.npz", z, xmin=-84.4, xmax=-84.4 + 40 * d, ymin=36.7, ymax=36.7 - 40 * d, d=d
    )
    grid = read_dem(path)
    assert grid.transform == pytest.approx((d, 0.0, -84.4, 0.0, -d, 36.7))
    cs = read_source(path, interval=50)
    top = max(cs.contours, key=lambda c: c.elevation)
    lonlat = make_transformer(cs.working_crs, "EPSG:4326")(top.coords)
    assert_allclose(lonlat.mean(axis=0), [-84.4 + 30.5 * d, 36.7 - 5.5 * d], atol=2e-5)


def test_npz_ascending_layout(tmp_path: Path) -> None:
    # ymin < ymax: row 0 sits at ymin, here the southern edge.
    d = 0.001
    z = cone(40, 40, peak_rc=(5, 30))
    path = write_npz(tmp_path / "south.npz", z, xmin=-84.4, xmax=-84.4 + 40 * d, ymin=36.66, ymax=36.7, d=d)
    assert read_dem(path).transform == pytest.approx((d, 0.0, -84.4, 0.0, d, 36.66))


def test_npz_pixel_centre_layout(tmp_path: Path) -> None:
    # Bounds spanning n - 1 pixels are the first and last pixel centres.
    d = 0.001
    z = cone(40, 40, peak_rc=(5, 30))
    path = write_npz(
        tmp_path / "c.npz", z, xmin=-84.4, xmax=-84.4 + 39 * d, ymin=36.7, ymax=36.7 - 39 * d, d=d
    )
    assert read_dem(path).transform == pytest.approx((d, 0.0, -84.4 - d / 2, 0.0, -d, 36.7 + d / 2))


def test_npz_inconsistent_bounds(tmp_path: Path) -> None:
    path = write_npz(
        tmp_path / "odd.npz", cone(10, 10, (5, 5)), xmin=0.0, xmax=0.5, ymin=1.0, ymax=0.0, d=0.01
    )
    with pytest.raises(SourceError, match=r"odd.npz: x bounds span 50.000 pixels"):
        read_source(path, interval=50)


def test_npz_missing_keys(tmp_path: Path) -> None:
    path = tmp_path / "keys.npz"
    np.savez(path, elevation=np.zeros((3, 3)), xmin=0.0)
    with pytest.raises(SourceError, match=r"keys.npz: not a DEM .npz: missing keys \['xmax'"):
        read_source(path, interval=10)


def test_npz_corrupt(tmp_path: Path) -> None:
    path = tmp_path / "corrupt.npz"
    path.write_bytes(b"PK\x03\x04 definitely not a zip")
    with pytest.raises(SourceError, match="corrupt.npz: cannot read DEM"):
        read_source(path, interval=10)


# ------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize("interval", [0, -5, float("nan"), float("inf")])
def test_bad_interval(tmp_path: Path, interval: float) -> None:
    path = write_tif(tmp_path / "c.tif", cone(10, 10, (5, 5)).astype(np.float32))
    with pytest.raises(InvalidParameter, match="interval"):
        contours_from_dem(path, interval=interval)


def test_dem_needs_an_interval(tmp_path: Path) -> None:
    path = write_tif(tmp_path / "c.tif", cone(10, 10, (5, 5)).astype(np.float32))
    with pytest.raises(InvalidParameter, match="c.tif: a DEM needs a contour interval"):
        read_source(path)


def test_too_many_levels(tmp_path: Path) -> None:
    path = write_tif(tmp_path / "c.tif", cone(10, 10, (5, 5)).astype(np.float32))
    with pytest.raises(InvalidParameter, match="levels"):
        contours_from_dem(path, interval=0.001)


def test_flat_dem_has_no_contour(tmp_path: Path) -> None:
    path = write_tif(tmp_path / "flat.tif", np.full((10, 10), 123.0, dtype=np.float32))
    with pytest.raises(
        SourceError, match=r"flat.tif: no contour at interval 50 within the DEM's range \[123, 123\]"
    ):
        read_source(path, interval=50)


def test_missing_and_unreadable_dem(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="missing.tif: file not found"):
        read_source(tmp_path / "missing.tif", interval=10)
    bad = tmp_path / "garbage.tif"
    bad.write_bytes(b"not a tiff")
    with pytest.raises(SourceError, match="garbage.tif: the file could not be read as a DEM"):
        read_source(bad, interval=10)
