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
from synthetic_rasters import write_exact_level_lines

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
