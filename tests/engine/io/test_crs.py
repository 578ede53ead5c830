"""Tests of engine.io.crs: the working CRS, transformers, and where coordinates are valid."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from engine.errors import SourceError
from engine.io.crs import (
    as_coords,
    choose_working_crs,
    crs_to_string,
    is_metric_projected,
    lonlat_validity,
    make_transformer,
    parse_crs,
)

JACKSBORO_BOUNDS = (-84.41375, 36.44625, -84.07792, 36.73292)


@pytest.mark.parametrize(
    ("source", "bounds", "expected"),
    [
        ("EPSG:4326", JACKSBORO_BOUNDS, "EPSG:32616"),  # centre lon -84.25: UTM 16N
        ("EPSG:4326", (-84.3, 36.0, -84.1, 37.0), "EPSG:32616"),  # lon -84.2, as the issue states
        ("EPSG:4326", (-83.9, 36.0, -83.7, 37.0), "EPSG:32617"),  # east of -84°: 17N
        ("EPSG:4326", (18.3, -34.0, 18.5, -33.8), "EPSG:32734"),  # Cape Town: southern hemisphere
        ("EPSG:4269", JACKSBORO_BOUNDS, "EPSG:32616"),  # NAD83 degrees: still a UTM zone
        ("EPSG:2263", (-74.1, 40.6, -73.9, 40.8), "EPSG:32618"),  # projected in US feet: not metres
        ("EPSG:32617", JACKSBORO_BOUNDS, "EPSG:32617"),  # projected in metres: the data's own
        ("EPSG:3857", JACKSBORO_BOUNDS, "EPSG:32616"),  # Web Mercator's metres are not metres
        ("EPSG:4326", (10.0, 85.0, 20.0, 88.0), "EPSG:32661"),  # beyond UTM: UPS North
        ("EPSG:4326", (10.0, -89.0, 20.0, -85.0), "EPSG:32761"),  # UPS South
    ],
)
def test_choose_working_crs(source: str, bounds: tuple[float, float, float, float], expected: str) -> None:
    assert choose_working_crs(source, bounds) == expected


def test_choose_working_crs_is_never_in_degrees() -> None:
    crs = pyproj.CRS(choose_working_crs("EPSG:4326", JACKSBORO_BOUNDS))
    assert is_metric_projected(crs)


def test_choose_working_crs_on_a_zone_boundary_is_stable() -> None:
    # Centre exactly on -84°: pyproj returns zones 16 and 17; the 6° rule says 17.
    assert choose_working_crs("EPSG:4326", (-84.1, 36.0, -83.9, 37.0)) == "EPSG:32617"


def test_choose_working_crs_keeps_a_custom_metric_crs_as_wkt() -> None:
    custom = pyproj.CRS.from_proj4("+proj=tmerc +lon_0=-84.2 +lat_0=36 +k=1 +ellps=GRS80 +units=m")
    chosen = choose_working_crs(custom.to_wkt(), JACKSBORO_BOUNDS)
    assert pyproj.CRS(chosen).equals(custom)


@pytest.mark.parametrize("bounds", [(np.nan, 0.0, 1.0, 1.0), (0.0, -95.0, 1.0, 1.0), (0.0, 10.0, 1.0, 5.0)])
def test_choose_working_crs_rejects_bad_bounds(bounds: tuple[float, float, float, float]) -> None:
    with pytest.raises(SourceError, match="bounds"):
        choose_working_crs("EPSG:4326", bounds)


@pytest.mark.parametrize("crs", ["EPSG:999999", "not a crs", ""])
def test_parse_crs_rejects_unknown_crs(crs: str) -> None:
    with pytest.raises(SourceError, match="my.shp"):
        parse_crs(crs, where="my.shp")


def test_parse_crs_keeps_the_horizontal_part_of_a_compound_crs() -> None:
    assert crs_to_string(parse_crs("EPSG:32616+5703")) == "EPSG:32616"


@pytest.mark.parametrize(
    ("crs", "expected"),
    [("OGC:CRS84", "EPSG:4326"), ("EPSG:4326", "EPSG:4326"), ("EPSG:32616", "EPSG:32616")],
)
def test_crs_to_string_names_authority(crs: str, expected: str) -> None:
    assert crs_to_string(pyproj.CRS(crs)) == expected


def test_make_transformer_is_always_xy() -> None:
    to_utm = make_transformer("EPSG:4326", "EPSG:32616")
    out = to_utm(np.array([[-87.0, 0.0], [-84.2, 36.5]]))
    assert out.shape == (2, 2)
    assert out.dtype == np.float64
    assert_allclose(out[0], [500_000.0, 0.0], atol=1e-6)  # central meridian on the equator
    assert 700_000 < out[1, 0] < 800_000 and 4_000_000 < out[1, 1] < 4_100_000


def test_make_transformer_identity_returns_a_copy() -> None:
    xy = np.array([[1.0, 2.0]])
    out = make_transformer("EPSG:32616", "EPSG:32616")(xy)
    assert_allclose(out, xy)
    out[0, 0] = 99.0
    assert xy[0, 0] == 1.0


def test_make_transformer_marks_failures_as_inf() -> None:
    to_lonlat = make_transformer("EPSG:32616", "EPSG:4326")
    out = to_lonlat(np.array([[1e20, 0.0], [500_000.0, 4_000_000.0]]))
    assert not np.isfinite(out[0]).all()
    assert np.isfinite(out[1]).all()


def test_make_transformer_accepts_empty_and_rejects_bad_shapes() -> None:
    f = make_transformer("EPSG:4326", "EPSG:3857")
    assert f(np.empty((0, 2))).shape == (0, 2)
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        f(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        as_coords([1.0, 2.0])


@settings(max_examples=50, deadline=None)
@given(
    lon=st.floats(min_value=-89.9, max_value=-84.1),
    lat=st.floats(min_value=0.5, max_value=80.0),
)
def test_transformer_round_trip_within_a_millimetre(lon: float, lat: float) -> None:
    forward = make_transformer("EPSG:4326", "EPSG:32616")
    back = make_transformer("EPSG:32616", "EPSG:4326")
    xy = forward(np.array([[lon, lat]]))
    assert_allclose(forward(back(xy)), xy, atol=1e-3)


def test_lonlat_validity_geographic() -> None:
    xy = np.array([[-84.2, 36.5], [-84.2, 95.0], [181.0, 0.0], [-180.0, -90.0]])
    lonlat, valid = lonlat_validity(pyproj.CRS("EPSG:4326"), xy)
    assert valid.tolist() == [True, False, False, True]
    assert np.isnan(lonlat[1]).all()


def test_lonlat_validity_projected() -> None:
    xy = np.array(
        [
            [750_000.0, 4_050_000.0],  # Tennessee
            [1e9, 4_050_000.0],  # does not invert
            [-3_000_000.0, 4_050_000.0],  # far outside the zone's area of use
            [500_000.0, -50_000.0],  # just south of the equator: near enough
        ]
    )
    lonlat, valid = lonlat_validity(pyproj.CRS("EPSG:32616"), xy)
    assert valid.tolist() == [True, False, False, True]
    assert_allclose(lonlat[0], [-84.2, 36.5], atol=0.3)


def test_lonlat_validity_web_mercator_beyond_the_square() -> None:
    # x beyond 20,037,508 m wraps to another longitude: the round trip catches it.
    _, valid = lonlat_validity(pyproj.CRS("EPSG:3857"), np.array([[3e7, 4e6], [-9.37e6, 4.4e6]]))
    assert valid.tolist() == [False, True]
