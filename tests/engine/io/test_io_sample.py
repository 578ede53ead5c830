"""Tests of the bundled sample: the Jacksboro DEM and its committed 20 m contours."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from engine.io.crs import make_transformer
from engine.io.source import contours_from_dem, read_source, sample_contours_path, sample_dem_path
from engine.types import ContourSet

#: Counts of the committed file (data/sample/README.md); make_sample.py prints them.
SAMPLE_LINES = 1830
SAMPLE_CLOSED = 1380


@pytest.fixture(scope="module")
def sample_set() -> ContourSet:
    return read_source(sample_contours_path())


@pytest.fixture(scope="module")
def dem_set() -> ContourSet:
    return contours_from_dem(sample_dem_path(), interval=20)


def test_sample_paths() -> None:
    assert sample_contours_path().name == "jacksboro_contours_20m.geojson"
    assert sample_dem_path().name == "jacksboro_fault_dem.npz"
    assert sample_contours_path().parent == sample_dem_path().parent  # the bundled copy, not matplotlib's


def test_sample_reads_back_as_made(sample_set: ContourSet, dem_set: ContourSet) -> None:
    assert len(sample_set.contours) == len(dem_set.contours) == SAMPLE_LINES
    assert (
        sum(c.closed for c in sample_set.contours) == sum(c.closed for c in dem_set.contours) == SAMPLE_CLOSED
    )
    assert sample_set.bad_features == []
    assert [c.id for c in sample_set.contours] == [c.id for c in dem_set.contours]
    assert [c.elevation for c in sample_set.contours] == [c.elevation for c in dem_set.contours]
    assert sample_set.working_crs == dem_set.working_crs == "EPSG:32616"
    assert sample_set.source_crs == dem_set.source_crs == "EPSG:4326"
    assert sample_set.interval == dem_set.interval == 20.0
    assert sample_set.name == "jacksboro_contours_20m"


def test_sample_geometry_matches_the_dem(sample_set: ContourSet, dem_set: ContourSet) -> None:
    # 6 decimals are about 11 cm of latitude; rounding may merge vertices a few centimetres apart.
    for a, b in zip(dem_set.contours[::50], sample_set.contours[::50], strict=True):
        assert b.n_vertices <= a.n_vertices
        assert np.abs(a.coords.min(axis=0) - b.coords.min(axis=0)).max() < 0.2
        assert np.abs(a.coords.max(axis=0) - b.coords.max(axis=0)).max() < 0.2


def test_sample_file_layout() -> None:
    text = sample_contours_path().read_text()
    doc = json.loads(text)
    assert "crs" not in doc
    props = doc["features"][0]["properties"]
    assert set(props) == {"id", "elevation"}
    coords = [xy for f in doc["features"][:20] for xy in f["geometry"]["coordinates"]]
    assert all(len(repr(v).split(".")[-1]) <= 6 for xy in coords for v in xy)


def test_sample_dem_orientation(dem_set: ContourSet) -> None:
    # The DEM's highest point (1076 m) is at row 297, column 219; with row 0 at the northern edge (ymin =
    # 36.733°) and edge-based bounds, its pixel centre is at (-84.41375 + 219.5 dx, 36.73292 - 297.5 dy).
    dem = np.load(sample_dem_path())
    row, col = np.unravel_index(np.argmax(dem["elevation"]), dem["elevation"].shape)
    assert (row, col) == (297, 219)
    expected = np.array([dem["xmin"] + (col + 0.5) * dem["dx"], dem["ymin"] - (row + 0.5) * dem["dy"]])
    top = [c for c in dem_set.contours if c.elevation == 1060.0]
    lonlat = make_transformer(dem_set.working_crs, "EPSG:4326")(np.vstack([c.coords for c in top]))
    assert np.abs(lonlat.mean(axis=0) - expected).max() < 0.003  # a few pixels
    assert lonlat[:, 1].min() > float(dem["ymax"])


def test_make_sample_script_exists() -> None:
    script = Path(sample_contours_path()).with_name("make_sample.py")
    text = script.read_text()
    assert "contours_from_dem" in text and "write_geojson" in text
