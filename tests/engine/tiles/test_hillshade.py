"""Hillshade: light from the north-west brightens slopes facing it; tiles sample the DEM in the right place."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from PIL import Image

from engine.errors import InvalidParameter
from engine.io.crs import crs_to_string
from engine.io.dem import read_dem
from engine.io.sample import sample_dem_path
from engine.tiles.grid import Tile
from engine.tiles.hillshade import hillshade_tile, shade_relief

#: A 1 km grid of 100 m cells in UTM 16N, north-up.
UTM = "EPSG:32616"
TRANSFORM = (100.0, 0.0, 500_000.0, 0.0, -100.0, 4_000_000.0)


def plane(dz_east: float, dz_north: float, n: int = 20) -> np.ndarray:
    """Heights (metres) of a plane rising dz_east per 100 m eastwards and dz_north per 100 m northwards."""
    cols, rows = np.meshgrid(np.arange(n), np.arange(n))
    return 500.0 + dz_east * cols - dz_north * rows  # row 0 is north


def test_flat_ground_is_white():
    relief = shade_relief(plane(0, 0), TRANSFORM, UTM)
    np.testing.assert_allclose(relief.shade, 1.0, atol=1e-6)


def test_a_slope_facing_the_light_is_brighter_than_one_facing_away():
    # A slope faces the way it falls: rising to the east and south, it faces the north-west light.
    facing_north_west = shade_relief(plane(20, -20), TRANSFORM, UTM).shade.mean()
    facing_south_east = shade_relief(plane(-20, 20), TRANSFORM, UTM).shade.mean()
    facing_north_east = shade_relief(plane(-20, -20), TRANSFORM, UTM).shade.mean()
    assert facing_north_west == pytest.approx(1.0)  # clipped: lit brighter than flat
    assert facing_north_east < 0.95 and facing_south_east < facing_north_east - 0.2


def test_no_data_stays_transparent_and_a_rotated_grid_is_refused():
    z = np.ma.masked_array(plane(5, 5), mask=False)
    z[3, 3] = np.ma.masked
    assert np.isnan(shade_relief(z, TRANSFORM, UTM).shade[3, 3])
    with pytest.raises(InvalidParameter, match="rotated"):
        shade_relief(plane(0, 0), (100.0, 5.0, 0.0, 0.0, -100.0, 0.0), UTM)


def tile_of(lon: float, lat: float, z: int) -> Tile:
    n = 1 << z
    x = int((lon + 180) / 360 * n)
    y = int((1 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2 * n)
    return Tile(z, x, y)


@pytest.fixture(scope="module")
def sample_relief():
    grid = read_dem(sample_dem_path())
    return shade_relief(grid.z, grid.transform, crs_to_string(grid.crs))


def test_sample_tile_is_opaque_over_the_dem_and_clear_off_it(sample_relief):
    # Zoom 10 tile holding the DEM's west edge (-84.414°) and north edge (36.733°, pixel row 133 of the
    # tile): along row 200 alpha is 255 east of the west edge and 0 west of it; rows north of 130 are clear.
    tile = tile_of(-84.41, 36.6, 10)
    img = np.asarray(Image.open(io.BytesIO(hillshade_tile(sample_relief, tile))))
    assert img.shape == (256, 256, 4)
    west_lon = tile.x / 1024 * 360 - 180
    edge_col = (-84.41375 - west_lon) / (360 / 1024) * 256
    assert (img[:130, :, 3] == 0).all() and (img[136:, -1, 3] == 255).all()
    alpha_row = img[200, :, 3]
    assert (alpha_row[: int(edge_col) - 1] == 0).all() and (alpha_row[int(edge_col) + 2 :] == 255).all()
    assert img[200, int(edge_col) + 2 :, 0].std() > 10  # relief, not a flat fill


def test_a_tile_far_from_the_dem_is_none(sample_relief):
    assert hillshade_tile(sample_relief, tile_of(10.0, 50.0, 10)) is None
