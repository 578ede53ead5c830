"""Contour sets from two real DEMs the engine was never tuned on, contoured the way ``gdal_contour`` does (at
the levels themselves, so lines of one level touch at saddle nodes): issue 13 is judged on data like these.

- Maunga Whau (Mt Eden, Auckland): the ``volcano`` grid of R's datasets package, bundled as
  ``tests/data/maunga_whau_nztm.asc`` (tests/data/README.md says how it was laid out).
- The Strait of Georgia / Salish Sea: matplotlib's sample ``topobathy.npz`` (topography and bathymetry),
  read from the installed matplotlib at test time.

A plain module (not conftest.py) so test modules and bench scripts can import it by name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import cbook
from synthetic_rasters import write_exact_level_lines, write_geotiff

from engine.io.dem import pixel_centres_to_crs, read_dem

MAUNGA_WHAU_ASC = Path(__file__).parent / "data" / "maunga_whau_nztm.asc"

#: Rows and columns of topobathy.npz kept by default (row 0 is the southern edge): 123.3-122.7 W, 49.3-49.8 N,
#: Howe Sound and the Coast Mountains north of Vancouver, from 200 m below sea level to 2,033 m, about 49 km
#: a side (the whole grid would make thousands of tiles at z13).
TOPOBATHY_WINDOW = (slice(60, 80), slice(80, 100))


def write_maunga_whau_contours(path: Path, interval: float) -> Path:
    """Maunga Whau's whole-metre heights contoured at multiples of ``interval``, in NZTM (EPSG:2193)."""
    grid = read_dem(MAUNGA_WHAU_ASC)

    def nztm(pts: np.ndarray) -> np.ndarray:
        return pixel_centres_to_crs(pts, grid.transform)

    return write_exact_level_lines(path, np.asarray(grid.z.filled()), interval, nztm, crs="EPSG:2193")


def topobathy() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(heights (rows, cols) in whole metres, longitude of each column in [-180, 180), latitude of each row)."""
    with np.load(cbook.get_sample_data("topobathy.npz", asfileobj=False)) as data:
        return data["topo"].astype(np.float64), data["longitude"] - 360.0, data["latitude"].astype(np.float64)


def write_topobathy_contours(path: Path, interval: float, window: tuple[slice, slice] = TOPOBATHY_WINDOW) -> Path:
    """Heights and depths of a window of topobathy.npz contoured at multiples of ``interval``, in lon/lat; the
    grid's own longitudes and latitudes place each node (the rows are not exactly evenly spaced)."""
    z, lon, lat = topobathy()
    z, lon, lat = z[window], lon[window[1]], lat[window[0]]

    def lonlat(pts: np.ndarray) -> np.ndarray:
        return np.column_stack(
            [np.interp(pts[:, 0], np.arange(len(lon)), lon), np.interp(pts[:, 1], np.arange(len(lat)), lat)]
        )

    return write_exact_level_lines(path, z, interval, lonlat)


# -- issue 24: more real terrain, each of another character, read from Debian's R packages at test time ----------

#: Debian's R packages install their data here (r-cran-terra, r-cran-fields).
R_SITE_LIBRARY = Path("/usr/lib/R/site-library")


def r_package_file(package: str, relative: str) -> Path:
    """A data file an installed R package ships; FileNotFoundError (the tests fail, never skip) naming the
    Debian package to install when it is missing."""
    path = R_SITE_LIBRARY / package / relative
    if not path.is_file():
        raise FileNotFoundError(f"{path} missing: apt-get install --no-install-recommends r-cran-{package.lower()}")
    return path


def luxembourg_dem() -> Path:
    """Luxembourg at 30 arc-seconds (``ex/elev.tif`` of R's terra, from SRTM, public domain; the package is
    GPL-3): 90 x 95 cells of whole metres 141-547 in lon/lat, nodata outside the country's border, so its edge
    is ragged nodata all round. A dissected plateau (the Ardennes' Oesling, the Gutland's valleys)."""
    return r_package_file("terra", "ex/elev.tif")


def _r_numbers(rda: Path, expression: str) -> np.ndarray:
    """The doubles ``expression`` gives once the ``.rda`` file is loaded, through Debian's Rscript (a dependency
    of the R packages): no R reader is needed in the venv."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "values.bin"
        script = f'load("{rda}"); writeBin(as.double({expression}), "{out}", endian = "little")'
        subprocess.run(["Rscript", "--vanilla", "-e", script], check=True, capture_output=True, timeout=60)
        return np.fromfile(out, dtype="<f8")


#: Rows and columns of RMelevation kept (row 0 north): the Front Range and the Continental Divide west of
#: Denver, about 105.2-106.0 W, 39.5-40.1 N: 1,700 m plains edge to 4,300 m peaks, about 64 km a side.
ROCKIES_WINDOW = (slice(120, 136), slice(120, 140))


def write_rocky_mountains_dem(path: Path, window: tuple[slice, slice] = ROCKIES_WINDOW) -> Path:
    """High mountains: ``RMelevation`` of R's fields package (PRISM 4 km grid of the Rocky Mountain region,
    Oregon State University's PRISM group via NCAR; the package is GPL >= 2), a window of it as a lon/lat
    GeoTIFF."""
    rda = r_package_file("fields", "data/RMelevation.rda")
    x, y = _r_numbers(rda, "RMelevation$x"), _r_numbers(rda, "RMelevation$y")
    z = _r_numbers(rda, "RMelevation$z").reshape(len(y), len(x))[::-1]  # R's z[x, y]; rows north first
    cell = float(np.mean(np.diff(x)))
    rows, cols = window
    north = float(y[::-1][rows.start]) + cell / 2
    west = float(x[cols.start]) - cell / 2
    return write_geotiff(path, z[window].astype("float32"), west=west, north=north, cell=cell, crs="EPSG:4326")


def write_glacier_dem(path: Path, n: int = 80) -> Path:
    """A glacier: Franke's glacier data of R's fields package (8,338 points digitized along a glacier's 1,300-
    2,100 m contours; its place and units are unknown, the package's documentation says), gridded linearly on
    n x n nodes (nodata outside the points' hull) and laid out in kilometres at a nominal place in UTM 32N."""
    from scipy.interpolate import griddata

    rda = r_package_file("fields", "data/glacier.rda")
    loc = _r_numbers(rda, "glacier$loc").reshape(2, -1).T
    height = _r_numbers(rda, "glacier$y")
    lo, hi = loc.min(axis=0), loc.max(axis=0)
    cell = float(np.max(hi - lo)) / (n - 1)
    cols, rows = np.meshgrid(np.arange(n), np.arange(n))
    nodes = np.column_stack([lo[0] + cols.ravel() * cell, hi[1] - rows.ravel() * cell])
    z = griddata(loc, height, nodes, method="linear").reshape(n, n)
    z = np.where(np.isnan(z), -9999.0, np.round(z)).astype("float32")
    west, north = 400_000.0 + lo[0] * 1000.0, 5_150_000.0 + hi[1] * 1000.0
    return write_geotiff(
        path,
        z,
        west=west - cell * 500.0,
        north=north + cell * 500.0,
        cell=cell * 1000.0,
        crs="EPSG:32632",
        nodata=-9999.0,
    )


def write_dem_window(source: Path, window: tuple[slice, slice], path: Path) -> Path:
    """Rows and columns ``window`` of any DEM the reader takes, as a GeoTIFF (nodata kept): a real DEM cut to a
    size whose tiles at every zoom from 1:1,000,000 to 1:40,000 a test can look at."""
    grid = read_dem(source)
    a, b, c, d, e, f = grid.transform
    rows, cols = window
    assert b == 0.0 and d == 0.0, "a north-up or south-up grid"
    z = np.asarray(grid.z.filled(-9999.0), dtype="float32")[window]
    west, north = c + a * cols.start, f + e * rows.start
    if e > 0:  # south-up rows: flip to north-up
        z, north = z[::-1], f + e * rows.stop
    return write_geotiff(path, z, west=west, north=north, cell=abs(a), crs=grid.crs.to_string(), nodata=-9999.0)
