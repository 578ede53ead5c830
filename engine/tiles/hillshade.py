"""Hillshade raster tiles (PNG) from a DEM grid, to lie under the contours.

The relief is shaded once on the DEM's own grid (the usual cartographic light: from the north-west, 45°
above the horizon), then every tile samples that shade bilinearly at its pixel centres. Heights and cell
sizes are both taken in metres: a geographic grid's cell size is converted at each row's latitude.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np
import pyproj
from numpy.typing import NDArray
from PIL import Image
from scipy import ndimage

from engine.errors import InvalidParameter
from engine.tiles.grid import Tile, mercator_to_lonlat, tile_bounds

#: Hillshade tiles are 256 px squares (the raster-tile convention every client expects).
HILLSHADE_TILE_PX = 256
#: Direction the light comes from, degrees clockwise from north, and its height above the horizon.
LIGHT_AZIMUTH_DEG = 315.0
LIGHT_ALTITUDE_DEG = 45.0
#: Heights are exaggerated this much: low hills on a 90 m grid would otherwise barely show.
Z_FACTOR = 2.0
#: Metres per degree of latitude (mean), and of longitude on the equator (WGS 84 sphere of equal area is
#: close enough for shading).
M_PER_DEG_LAT = 111_132.0
M_PER_DEG_LON_EQUATOR = 111_320.0


@dataclass(frozen=True)
class ShadedRelief:
    """A DEM's hillshade on its own grid."""

    #: (rows, cols) float32 brightness in [0, 1] (1 on flat ground and slopes facing the light); NaN where the DEM has
    #: no data.
    shade: NDArray[np.float32]
    #: (a, b, c, d, e, f) GDAL geotransform of the grid (pixel edges), in ``crs``.
    transform: tuple[float, float, float, float, float, float]
    #: The grid's CRS (any pyproj understands).
    crs: str


def shade_relief(
    heights: np.ma.MaskedArray | NDArray[np.float64],
    transform: tuple[float, float, float, float, float, float],
    crs: str,
) -> ShadedRelief:
    """Shade a DEM: the cosine of the angle between the light and the ground's normal, divided by its value on
    flat ground and clipped to [0, 1].

    Parameters
    ----------
    heights
        (rows, cols) heights in metres, masked or NaN where there is no data.
    transform
        GDAL geotransform (north-up grids only: b = d = 0).
    crs
        The grid's CRS: geographic (degrees) or projected in metres.

    Raises
    ------
    InvalidParameter
        A rotated grid, or fewer than 2 x 2 cells.
    """
    a, b, _, d, e, f = transform
    if b or d:
        raise InvalidParameter(f"hillshade needs a north-up grid; the geotransform {transform} is rotated")
    z: NDArray[np.float64] = np.ma.filled(np.ma.masked_invalid(np.ma.asarray(heights, dtype=float)), np.nan)
    if z.ndim != 2 or min(z.shape) < 2:
        raise InvalidParameter(f"hillshade needs a grid of at least 2 x 2 cells, got shape {z.shape}")
    dx_m, dy_m = abs(a), abs(e)
    if pyproj.CRS.from_user_input(crs).is_geographic:
        row_lat = f + e * (np.arange(z.shape[0]) + 0.5)
        dx_m = abs(a) * M_PER_DEG_LON_EQUATOR * np.cos(np.radians(row_lat))[:, None]
        dy_m = abs(e) * M_PER_DEG_LAT
    # np.gradient runs along the grid's rows and columns; y = f + e * row, so the sign of e (negative on a
    # north-up grid) turns the per-row change into a northward slope, and the sign of a the per-column one.
    dz_row, dz_col = np.gradient(z * Z_FACTOR)
    dz_dx = dz_col / dx_m * math.copysign(1.0, a)
    dz_dy = dz_row / dy_m * math.copysign(1.0, e)
    slope = np.arctan(np.hypot(dz_dx, dz_dy))
    aspect = np.arctan2(-dz_dx, -dz_dy)  # the direction the ground faces, clockwise from north
    zenith = math.radians(90.0 - LIGHT_ALTITUDE_DEG)
    azimuth = math.radians(LIGHT_AZIMUTH_DEG)
    lit = math.cos(zenith) * np.cos(slope) + math.sin(zenith) * np.sin(slope) * np.cos(azimuth - aspect)
    # Scaled so that flat ground is white: only slopes turned from the light darken the paper under the lines.
    shade = lit / math.cos(zenith)
    shade = np.where(np.isnan(z), np.nan, np.clip(shade, 0.0, 1.0))  # central differences skip the cell itself
    return ShadedRelief(shade.astype(np.float32), transform, crs)


def hillshade_tile(relief: ShadedRelief, tile: Tile) -> bytes | None:
    """One 256 px PNG tile (grey, with alpha 0 outside the DEM), or None when the tile misses the DEM."""
    bounds = tile_bounds(tile)
    step = (bounds.maxx - bounds.minx) / HILLSHADE_TILE_PX
    centres = (np.arange(HILLSHADE_TILE_PX) + 0.5) * step
    mx, my = np.meshgrid(bounds.minx + centres, bounds.maxy - centres)
    lon, lat = mercator_to_lonlat(mx, my)
    gx, gy = lon, lat
    if not pyproj.CRS.from_user_input(relief.crs).is_geographic:
        to_grid = pyproj.Transformer.from_crs("EPSG:4326", relief.crs, always_xy=True)
        gx, gy = to_grid.transform(lon, lat)
    a, _, c, _, e, f = relief.transform
    col = (np.asarray(gx) - c) / a - 0.5  # fractional index of the cell centres
    row = (np.asarray(gy) - f) / e - 0.5
    rows, cols = relief.shade.shape
    inside = (col >= -0.5) & (col <= cols - 0.5) & (row >= -0.5) & (row <= rows - 0.5)
    if not inside.any():
        return None
    shade = ndimage.map_coordinates(relief.shade, [row, col], order=1, mode="nearest")
    inside &= np.isfinite(shade)
    if not inside.any():
        return None
    grey = np.where(inside, np.rint(np.nan_to_num(shade) * 255), 0).astype(np.uint8)
    alpha = np.where(inside, 255, 0).astype(np.uint8)
    out = io.BytesIO()
    Image.fromarray(np.dstack([grey, grey, grey, alpha]), "RGBA").save(out, format="PNG")
    return out.getvalue()
