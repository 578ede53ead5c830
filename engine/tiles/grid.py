"""Web Mercator tile math, quantisation to the tile grid and clipping (the mercantile conventions).

Tiles are XYZ (``y = 0`` at the north edge), EPSG:3857 metres. A tile's grid has ``extent`` units per side
(4096 by default), y pointing down as MVT wants it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from engine.errors import InvalidParameter, TileOutOfRange
from engine.types import Bounds

#: Half the width of the Web Mercator square, metres (pi x 6378137).
HALF_WORLD_M = math.pi * 6378137.0
#: Largest tile zoom any request may name (the tile matrix of z 30 already has 1e9 columns).
MAX_TILE_ZOOM = 30
#: Web Mercator's latitude limit, degrees.
MAX_LATITUDE_DEG = 85.0511287798066


class Tile(NamedTuple):
    """An XYZ tile index: zoom ``z``, column ``x`` (west to east), row ``y`` (north to south)."""

    z: int
    x: int
    y: int


def check_tile(z: int, x: int, y: int, min_zoom: int = 0, max_zoom: int = MAX_TILE_ZOOM) -> Tile:
    """Validate a tile index against its zoom's tile matrix and the served zoom range.

    >>> check_tile(1, 1, 0)
    Tile(z=1, x=1, y=0)

    Raises
    ------
    TileOutOfRange
        ``z`` outside [min_zoom, max_zoom], or ``x``/``y`` outside [0, 2^z - 1]; the message names the value.
    """
    if not min_zoom <= z <= max_zoom:
        raise TileOutOfRange(f"zoom {z} is outside the served range [{min_zoom}, {max_zoom}]")
    n = 1 << z
    if not 0 <= x < n:
        raise TileOutOfRange(f"x {x} is outside [0, {n - 1}] at zoom {z}")
    if not 0 <= y < n:
        raise TileOutOfRange(f"y {y} is outside [0, {n - 1}] at zoom {z}")
    return Tile(z, x, y)


def check_fractional_zoom(z: int, zoom: float | None) -> float:
    """The zoom a tile is drawn at: ``zoom`` if given (it must lie in [z, z + 1)), else ``z``.

    Raises
    ------
    InvalidParameter
        ``zoom`` is not finite or outside [z, z + 1).
    """
    if zoom is None:
        return float(z)
    value = float(zoom)
    if not math.isfinite(value) or not z <= value < z + 1:
        raise InvalidParameter(f"zoom {zoom} must lie in [{z}, {z + 1}) for a tile of zoom {z}")
    return value


def tile_bounds(tile: Tile) -> Bounds:
    """EPSG:3857 bounds of a tile, metres.

    >>> tile_bounds(Tile(0, 0, 0)).maxx == HALF_WORLD_M
    True
    """
    size = 2 * HALF_WORLD_M / (1 << tile.z)
    minx = -HALF_WORLD_M + tile.x * size
    maxy = HALF_WORLD_M - tile.y * size
    return Bounds(minx, maxy - size, minx + size, maxy)


def buffered(bounds: Bounds, buffer_px: int, extent: int) -> Bounds:
    """The tile bounds grown by ``buffer_px`` grid units on each side (same units as ``bounds``)."""
    pad = (bounds.maxx - bounds.minx) * buffer_px / extent
    return Bounds(bounds.minx - pad, bounds.miny - pad, bounds.maxx + pad, bounds.maxy + pad)


def tile_center_latitude(tile: Tile) -> float:
    """Latitude of a tile's centre, degrees (the latitude its map scale is computed at)."""
    n = 1 << tile.z
    return math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * (tile.y + 0.5) / n))))


def mercator_to_lonlat(
    x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """EPSG:3857 metres to longitude/latitude degrees (spherical formulas, exact for Web Mercator)."""
    lon = np.degrees(np.asarray(x, dtype=float) / 6378137.0)
    lat = np.degrees(np.arctan(np.sinh(np.asarray(y, dtype=float) / 6378137.0)))
    return lon, lat


def lonlat_to_mercator(
    lon: NDArray[np.float64], lat: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Longitude/latitude degrees to EPSG:3857 metres (latitude clamped to Web Mercator's range)."""
    lat_c = np.clip(np.asarray(lat, dtype=float), -MAX_LATITUDE_DEG, MAX_LATITUDE_DEG)
    x = np.radians(np.asarray(lon, dtype=float)) * 6378137.0
    y = np.log(np.tan(np.pi / 4 + np.radians(lat_c) / 2)) * 6378137.0
    return x, y


def tiles_covering(bounds_3857: Bounds, z: int) -> list[Tile]:
    """Every tile of zoom ``z`` that intersects an EPSG:3857 rectangle, row by row."""
    n = 1 << z
    size = 2 * HALF_WORLD_M / n

    def col(v: float) -> int:
        return min(n - 1, max(0, int(math.floor((v + HALF_WORLD_M) / size))))

    def row(v: float) -> int:
        return min(n - 1, max(0, int(math.floor((HALF_WORLD_M - v) / size))))

    x0, x1 = col(bounds_3857.minx), col(bounds_3857.maxx)
    y0, y1 = row(bounds_3857.maxy), row(bounds_3857.miny)
    return [Tile(z, x, y) for y in range(y0, y1 + 1) for x in range(x0, x1 + 1)]


def quantize(coords: NDArray[np.float64], bounds: Bounds, extent: int) -> NDArray[np.int64]:
    """EPSG:3857 coordinates to integer tile-grid coordinates, y down: (n, 2) int64.

    >>> b = Bounds(0.0, 0.0, 4096.0, 4096.0)
    >>> quantize(np.array([[0.0, 4096.0], [10.4, 0.0]]), b, 4096).tolist()
    [[0, 0], [10, 4096]]
    """
    k = extent / (bounds.maxx - bounds.minx)
    out = np.empty(coords.shape, dtype=np.int64)
    np.rint((coords[:, 0] - bounds.minx) * k, out=out[:, 0], casting="unsafe")
    np.rint((bounds.maxy - coords[:, 1]) * k, out=out[:, 1], casting="unsafe")
    return out


def drop_repeats(q: NDArray[np.int64]) -> NDArray[np.int64]:
    """Drop consecutive duplicate rows of integer coordinates (the first of each run stays)."""
    if len(q) < 2:
        return q
    keep = np.empty(len(q), dtype=bool)
    keep[0] = True
    np.any(q[1:] != q[:-1], axis=1, out=keep[1:])
    return q if keep.all() else q[keep]


