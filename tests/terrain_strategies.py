"""Terrain the code was not written against: hypothesis strategies of small DEMs and contour sets with the hard
cases real data has (issue 24).

Each :class:`TerrainCase` is a seeded generator (one of :data:`KINDS`) placed somewhere on the globe, written as
a GeoTIFF DEM or as ``gdal_contour``-like GeoJSON lines of that DEM. Hypothesis draws the kind, the seed, the
size, the place and the file type, so a failing example is shrunk to a small, named one and can be pinned with
``@example(TerrainCase(...))``.

Profiles (env ``CCSM_HYPOTHESIS_PROFILE``): ``ci`` (the default: a fixed, derandomized budget, a few minutes on two
cores) and ``nightly`` (many more examples, random). A plain module (not conftest.py) so test modules import it by
name.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from synthetic_rasters import fractal_heights, write_exact_level_lines, write_geotiff

from engine.io.dem import pixel_centres_to_crs

settings.register_profile(
    "ci",
    max_examples=30,
    derandomize=True,
    deadline=None,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.register_profile(
    "nightly",
    max_examples=300,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
#: The settings of the whole-terrain tests: the profile named by CCSM_HYPOTHESIS_PROFILE, ``ci`` by default.
TERRAIN_SETTINGS = settings.get_profile(os.environ.get("CCSM_HYPOTHESIS_PROFILE", "ci"))

NODATA = -9999.0


@dataclass(frozen=True)
class Place:
    """Where a DEM lies: CRS, north-west corner and cell size in the CRS's unit."""

    crs: str
    west: float
    north: float
    cell: float


#: Places of real trouble: lon/lat across the antimeridian (east and west of it), beyond 80 degrees north and
#: south, across the equator (a scale is reached at the largest zoom there), a mid-latitude grid, a projected one.
PLACES = {
    "utm-33n": Place("EPSG:32633", 500_000.0, 5_200_000.0, 30.0),
    "lonlat-alps": Place("EPSG:4326", 10.0, 47.0, 1 / 1200),
    "lonlat-equator": Place("EPSG:4326", 9.5, 0.01, 1 / 3600),  # Gabon at 1" (SRTM 30 m), across the equator
    "lonlat-antimeridian-east": Place("EPSG:4326", 179.97, -16.5, 1 / 1200),  # runs past +180 (Fiji)
    "lonlat-antimeridian-west": Place("EPSG:4326", -180.0, 65.5, 1 / 1200),  # starts at -180 (Chukotka)
    "lonlat-arctic": Place("EPSG:4326", 20.0, 84.0, 1 / 1200),  # north of 80 N (Svalbard's sea)
    "lonlat-antarctic": Place("EPSG:4326", 160.0, -81.0, 1 / 1200),  # south of 80 S (Ross Ice Shelf)
}


@dataclass(frozen=True)
class TerrainCase:
    """One generated terrain: which generator, its seed and side, where it lies, how it is contoured and
    written."""

    kind: str
    seed: int
    n: int
    place: str
    as_lines: bool  # True: gdal_contour-like GeoJSON lines of the DEM; False: the DEM as a GeoTIFF

    @property
    def interval(self) -> float:
        """Contour interval in the terrain's unit."""
        return KINDS[self.kind].interval

    @property
    def units(self) -> str:
        """Vertical unit, "m" or "ft"."""
        return KINDS[self.kind].units

    def heights(self) -> np.ndarray:
        """(n, n) float32 heights, NaN where there are no data."""
        return KINDS[self.kind].make(np.random.default_rng(self.seed), self.n).astype(np.float32)

    def write(self, folder: Path) -> Path:
        """The terrain as a source file in ``folder``: a GeoTIFF with a nodata value, or GeoJSON lines."""
        z = self.heights()
        place = PLACES[self.place]
        name = f"{self.kind}-{self.place}-{self.seed}"
        if not self.as_lines:
            filled = np.where(np.isnan(z), np.float32(NODATA), z)
            return write_geotiff(
                folder / f"{name}.tif",
                filled,
                west=place.west,
                north=place.north,
                cell=place.cell,
                crs=place.crs,
                nodata=NODATA,
            )
        transform = _transform(place)

        def to_crs(pts: np.ndarray) -> np.ndarray:
            return pixel_centres_to_crs(pts, transform)

        crs = None if place.crs == "EPSG:4326" else place.crs
        return write_exact_level_lines(folder / f"{name}.geojson", _contourable(z), self.interval, to_crs, crs=crs)


def _transform(place: Place) -> tuple[float, float, float, float, float, float]:
    """The grid's affine coefficients (a, b, c, d, e, f), north up, as :class:`engine.io.dem.DemGrid` keeps them."""
    return (place.cell, 0.0, place.west, 0.0, -place.cell, place.north)


def _contourable(z: np.ndarray) -> np.ndarray:
    """Heights for contourpy, which has no nodata: a hole becomes a deep pit far below every level (lines ring
    it as gdal_contour's do not, but what matters here is that the engine takes such lines)."""
    return np.where(np.isnan(z), np.nanmin(z) - 1000.0, z).astype(np.float64)


@dataclass(frozen=True)
class Kind:
    """A terrain generator: (rng, side) -> heights, and the interval and unit it is contoured at."""

    make: Callable[[np.random.Generator, int], np.ndarray]
    interval: float
    units: str = "m"


def _fractal(rng: np.random.Generator, n: int, beta: float = 2.8, relief: float = 300.0) -> np.ndarray:
    return fractal_heights(int(rng.integers(1 << 30)), beta, n=n, relief_m=relief) - 200.0


def bathymetry(rng: np.random.Generator, n: int) -> np.ndarray:
    """Land and sea floor: a coastline at 0, negative and zero levels, the sea surface itself flat at 0 where a
    DEM clips it (as SRTM does), then a shelf below."""
    z = _fractal(rng, n, relief=240.0) - 120.0
    z[(z > -15.0) & (z < 0.0)] = 0.0  # a flat sea surface exactly on the zero level
    return z


def plateaus(rng: np.random.Generator, n: int) -> np.ndarray:
    """Terraces exactly on the levels: flats at 20 m steps, many rings of one level touching each other."""
    return np.floor(_fractal(rng, n, relief=160.0) / 20.0) * 20.0


def cliffs(rng: np.random.Generator, n: int) -> np.ndarray:
    """A cliff: 200 m over one cell on a bending line, ten levels stacked closer than a pixel at any zoom."""
    rows, cols = np.mgrid[0:n, 0:n]
    edge = n / 2 + n / 6 * np.sin(rows / n * rng.uniform(2.0, 7.0))
    return np.where(cols > edge, 200.0, 0.0) + _fractal(rng, n, relief=15.0)


def nodata(rng: np.random.Generator, n: int) -> np.ndarray:
    """Hills with nodata holes inside and a ragged nodata edge."""
    z = _fractal(rng, n, relief=200.0)
    rows, cols = np.mgrid[0:n, 0:n]
    for _ in range(int(rng.integers(1, 5))):
        r, c, radius = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(2.0, n / 6)
        z[np.hypot(rows - r, cols - c) < radius] = np.nan
    z[:, : int(rng.integers(1, 4))] = np.nan  # a void strip at the west edge
    z[np.arange(n), np.clip(n - 1 - rng.integers(0, 4, n), 0, n - 1)] = np.nan  # a ragged east edge
    return z


def islands_and_pits(rng: np.random.Generator, n: int) -> np.ndarray:
    """A flat at 5 m with single-cell islands (15 m) and pits (-5 m): rings of a few metres."""
    z = np.full((n, n), 5.0)
    cells = rng.integers(1, n - 1, size=(int(rng.integers(3, 20)), 2))
    z[cells[:, 0], cells[:, 1]] = rng.choice([15.0, -5.0], size=len(cells))
    return z


def one_long_contour(rng: np.random.Generator, n: int) -> np.ndarray:
    """A serpentine dyke one cell wide across the whole DEM (its 10 m line is far longer than the rest) and a
    few small knolls."""
    z = np.zeros((n, n))
    step = int(rng.integers(3, 6))
    for k, row in enumerate(range(1, n - 1, step)):
        z[row, 1 : n - 1] = 20.0
        turn = n - 2 if k % 2 == 0 else 1
        z[row : min(row + step, n - 1), turn] = 20.0
    for r, c in rng.integers(2, n - 2, size=(3, 2)):
        z[r, c] = 20.0
    return z


def tiny_everything(rng: np.random.Generator, n: int) -> np.ndarray:
    """Only specks: bumps of one or two cells on a flat, all far smaller than 1:500,000 keeps and none long
    enough to carry a label; each peaks a hair above the 5 m index level, so that level's rings are
    centimetres across (as a DEM's peak just above a level gives)."""
    z = np.zeros((n, n))
    cells = rng.integers(1, n - 2, size=(int(rng.integers(1, 12)), 2))
    z[cells[:, 0], cells[:, 1]] = 5.0 + rng.uniform(0.001, 0.1, size=len(cells))
    z[cells[:, 0], cells[:, 1] + 1] = rng.choice([0.0, 2.0], size=len(cells))
    return z


def few_levels(rng: np.random.Generator, n: int) -> np.ndarray:
    """Rugged relief of 300 m contoured at 250 m: one or two levels."""
    return _fractal(rng, n, beta=2.4, relief=300.0) + 100.0


def feet(rng: np.random.Generator, n: int) -> np.ndarray:
    """Heights in feet at a 40 ft interval."""
    return np.round(_fractal(rng, n, relief=250.0) * 3.28084)


def single_contour(rng: np.random.Generator, n: int) -> np.ndarray:
    """One cone crossing one level: a single ring."""
    rows, cols = np.mgrid[0:n, 0:n]
    r, c = rng.uniform(n / 3, 2 * n / 3, 2)
    return 100.0 - np.hypot(rows - r, cols - c) * rng.uniform(2.0, 5.0)


def one_level(rng: np.random.Generator, n: int) -> np.ndarray:
    """Several knolls reaching 60-90 m, contoured at 50 m: many rings, all of one level."""
    rows, cols = np.mgrid[0:n, 0:n]
    z = np.zeros((n, n))
    for _ in range(int(rng.integers(2, 7))):
        r, c = rng.uniform(0, n, 2)
        z = np.maximum(z, rng.uniform(60.0, 90.0) - np.hypot(rows - r, cols - c) * rng.uniform(3.0, 10.0))
    return z


KINDS = {
    "bathymetry": Kind(bathymetry, 20.0),
    "plateaus": Kind(plateaus, 20.0),
    "cliffs": Kind(cliffs, 20.0),
    "nodata": Kind(nodata, 20.0),
    "islands-and-pits": Kind(islands_and_pits, 10.0),
    "one-long-contour": Kind(one_long_contour, 10.0),
    "tiny-everything": Kind(tiny_everything, 1.0),
    "few-levels": Kind(few_levels, 250.0),
    "feet": Kind(feet, 40.0, units="ft"),
    "single-contour": Kind(single_contour, 50.0),
    "one-level": Kind(one_level, 50.0),
}


def terrains(max_side: int = 80) -> st.SearchStrategy[TerrainCase]:
    """Any kind at any place, 40 to ``max_side`` cells a side, as a DEM or as its contour lines."""
    return st.builds(
        TerrainCase,
        kind=st.sampled_from(sorted(KINDS)),
        seed=st.integers(0, 2**16),
        n=st.integers(40, max_side),
        place=st.sampled_from(sorted(PLACES)),
        as_lines=st.booleans(),
    )
