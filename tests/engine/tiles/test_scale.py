"""Tests of engine.tiles.scale: zoom <-> scale denominator at 512 px tiles and the 0.28 mm OGC pixel."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidParameter
from engine.tiles.scale import scale_for_zoom, zoom_for_scale

HYPOTHESIS = settings(deadline=None, max_examples=80)
latitudes = st.floats(-85.0, 85.0)


def expected_scale(zoom: float, lat_deg: float) -> float:
    """docs/design.md section 4, written out: ground metres per 512 px tile pixel over 0.28 mm."""
    metres_per_pixel = 2.0 * math.pi * 6378137.0 * math.cos(math.radians(lat_deg)) / (512.0 * 2.0**zoom)
    return metres_per_pixel / 0.00028


@pytest.mark.parametrize(("zoom", "lat"), [(0.0, 0.0), (12.1, 36.6), (8.8, 36.6), (17.5, -60.0)])
def test_scale_for_zoom_follows_the_ground_resolution_formula(zoom: float, lat: float) -> None:
    assert float(scale_for_zoom(zoom, lat)) == pytest.approx(expected_scale(zoom, lat), rel=1e-12)


def test_scale_at_zoom_zero_on_the_equator_is_about_279_million() -> None:
    assert float(scale_for_zoom(0, 0.0)) == pytest.approx(279_541_132, abs=1.0)


@pytest.mark.parametrize(("scale", "zoom"), [(50_000, 12.1), (500_000, 8.8)])
def test_design_examples_at_latitude_36_6(scale: float, zoom: float) -> None:
    assert float(zoom_for_scale(scale, 36.6)) == pytest.approx(zoom, abs=0.05)


@given(st.floats(0.0, 24.0), latitudes)
@HYPOTHESIS
def test_zoom_scale_round_trip_from_zoom(zoom: float, lat: float) -> None:
    assert float(zoom_for_scale(scale_for_zoom(zoom, lat), lat)) == pytest.approx(zoom, abs=1e-9)


@given(st.floats(100.0, 1e9), latitudes)
@HYPOTHESIS
def test_zoom_scale_round_trip_from_scale(scale: float, lat: float) -> None:
    assert float(scale_for_zoom(zoom_for_scale(scale, lat), lat)) == pytest.approx(scale, rel=1e-9)


@given(st.floats(0.0, 24.0), st.floats(1e-6, 5.0), latitudes)
@HYPOTHESIS
def test_scale_decreases_as_zoom_increases(zoom: float, step: float, lat: float) -> None:
    assert scale_for_zoom(zoom + step, lat) < scale_for_zoom(zoom, lat)


def test_one_zoom_level_halves_the_scale() -> None:
    assert float(scale_for_zoom(11.0, 36.6) / scale_for_zoom(12.0, 36.6)) == pytest.approx(2.0, rel=1e-12)


def test_scale_for_zoom_is_vectorised() -> None:
    zooms = np.array([8.0, 10.0, 12.0])
    got = scale_for_zoom(zooms, 36.6)
    assert got.shape == (3,)
    np.testing.assert_allclose(got, [expected_scale(z, 36.6) for z in zooms], rtol=1e-12)


@pytest.mark.parametrize("lat", [85.1, -86.0, 90.0, float("nan")])
def test_latitude_outside_web_mercator_raises(lat: float) -> None:
    with pytest.raises(InvalidParameter, match="latitude"):
        scale_for_zoom(10.0, lat)
    with pytest.raises(InvalidParameter, match="latitude"):
        zoom_for_scale(50_000, lat)


@pytest.mark.parametrize("scale", [0.0, -1.0, float("inf"), float("nan")])
def test_non_positive_or_non_finite_scale_raises(scale: float) -> None:
    with pytest.raises(InvalidParameter, match="scale"):
        zoom_for_scale(scale, 36.6)
