"""Vertical units from a source's own metadata (issue 11, docs/design.md section 9.4)."""

import numpy as np
import pytest
import rasterio
from affine import Affine

from engine.cartography.units import source_units
from engine.io.vertical_units import units_from_field_name


@pytest.mark.parametrize(
    ("name", "units"),
    [
        ("ELEV_FT", "ft"),
        ("elevation_feet", "ft"),
        ("Contour Foot", "ft"),
        ("height_m", "m"),
        ("elev_metres", "m"),
        ("ele", None),
        ("ft", None),
        ("elev_ft_m", None),
        ("elevation", None),
    ],
)
def test_units_from_the_elevation_attribute_name(name, units):
    assert units_from_field_name(name) == units


def write_dem(path, *, band_unit=None, crs="EPSG:32616"):
    z = np.add.outer(np.arange(20.0), np.arange(20.0)) * 10
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=20,
        height=20,
        count=1,
        dtype="float64",
        crs=crs,
        transform=Affine(30.0, 0.0, 500_000.0, 0.0, -30.0, 4_000_000.0),
    ) as dst:
        dst.write(z, 1)
        if band_unit:
            dst.units = (band_unit,)
    return path


def test_dem_units_from_the_band_unit(tmp_path):
    assert source_units(write_dem(tmp_path / "ft.tif", band_unit="ft")) == "ft"
    assert source_units(write_dem(tmp_path / "m.tif", band_unit="metre")) == "m"
    assert source_units(write_dem(tmp_path / "none.tif")) is None


def test_dem_units_from_a_compound_crs_with_a_vertical_axis_in_feet(tmp_path):
    # NAD83 / UTM 16N + NAVD88 height (ftUS): the vertical axis says US survey feet.
    assert source_units(write_dem(tmp_path / "compound.tif", crs="EPSG:26916+6360")) == "ft"
