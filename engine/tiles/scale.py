"""Map zoom <-> scale denominator (docs/design.md section 4).

MapLibre draws vector tiles at 512 px; the OGC standard pixel is 0.28 mm. At latitude φ one pixel of zoom z
covers 2π·6378137·cos φ / (512 · 2^z) metres on the ground, so the scale denominator is that divided by
0.00028 m. Fractional zooms are valid.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.errors import InvalidParameter

EARTH_RADIUS_M = 6378137.0
TILE_SIZE_PX = 512
OGC_PIXEL_M = 0.00028

#: Scale denominator at zoom 0 on the equator (about 279,541,132).
SCALE_AT_Z0 = 2 * math.pi * EARTH_RADIUS_M / TILE_SIZE_PX / OGC_PIXEL_M


def _check_latitude(lat_deg: float) -> None:
    if not -85.06 <= lat_deg <= 85.06:
        raise InvalidParameter(f"latitude {lat_deg} is outside Web Mercator's range [-85.06, 85.06]")


def scale_for_zoom(zoom: ArrayLike, lat_deg: float) -> NDArray[np.float64]:
    """Scale denominator at a (fractional) zoom and latitude.

    >>> round(float(scale_for_zoom(12.1, 36.6)))
    52439
    """
    _check_latitude(lat_deg)
    return SCALE_AT_Z0 * math.cos(math.radians(lat_deg)) / np.power(2.0, np.asarray(zoom, dtype=float))


def zoom_for_scale(scale: ArrayLike, lat_deg: float) -> NDArray[np.float64]:
    """Fractional zoom at which the map shows a scale denominator at a latitude.

    >>> round(float(zoom_for_scale(500_000, 36.6)), 1)
    8.8
    """
    _check_latitude(lat_deg)
    s = np.asarray(scale, dtype=float)
    if np.any(~np.isfinite(s)) or np.any(s <= 0):
        raise InvalidParameter(f"scale must be a positive finite number, got {scale!r}")
    return np.log2(SCALE_AT_Z0 * math.cos(math.radians(lat_deg)) / s)
