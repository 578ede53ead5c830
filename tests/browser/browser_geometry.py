"""Geometry measures for the browser tests: how far the rendered contours moved between two frames.

Frames are lists of polylines in (lon, lat) degrees, as MapLibre's ``queryRenderedFeatures`` returns them.
They are projected to Web Mercator pixels at a fixed reference zoom, so the measure does not change when the
map zooms: only a change of the contour geometry itself moves it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

#: Pixels of the reference zoom that the frames are compared in (MapLibre's 512 px tiles).
REFERENCE_ZOOM = 12.0
#: Spacing, in reference pixels, of the points a polyline is densified to before nearest-point look-ups.
DENSIFY_PX = 0.5

Polyline = Sequence[Sequence[float]]


def lonlat_to_px(coords: NDArray[np.float64], zoom: float = REFERENCE_ZOOM) -> NDArray[np.float64]:
    """(n, 2) lon/lat degrees to (n, 2) Web Mercator pixels at ``zoom`` (512 px world at zoom 0)."""
    world = 512.0 * 2.0**zoom
    lon = coords[:, 0]
    lat = np.clip(coords[:, 1], -85.05112878, 85.05112878)
    x = (lon + 180.0) / 360.0 * world
    y = (1.0 - np.log(np.tan(np.radians(lat)) + 1.0 / np.cos(np.radians(lat))) / math.pi) / 2.0 * world
    return np.column_stack([x, y])


def densify(line_px: NDArray[np.float64], spacing: float = DENSIFY_PX) -> NDArray[np.float64]:
    """Points along a (n, 2) polyline at most ``spacing`` apart, vertices included."""
    if len(line_px) < 2:
        return line_px
    seg = np.diff(line_px, axis=0)
    steps = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / spacing).astype(int))
    parts = [line_px[i] + np.outer(np.arange(k) / k, seg[i]) for i, k in enumerate(steps)]
    parts.append(line_px[-1:])
    return np.concatenate(parts)


def tile_grid_px(z: int, extent: int = 4096, zoom: float = REFERENCE_ZOOM) -> float:
    """Size, in pixels of ``zoom``, of one MVT grid unit of a tile of zoom ``z`` (512 px tiles)."""
    return 512.0 * 2.0 ** (zoom - z) / extent


def frame_points(
    lines: Sequence[Polyline], box_px: tuple[float, float, float, float], grid_px: float | None = None
) -> NDArray[np.float64]:
    """All densified points of a frame's polylines that fall inside ``box_px`` (minx, miny, maxx, maxy).

    ``grid_px`` snaps the vertices to a grid first. Frames drawn from tiles of different zooms are rounded to
    different MVT grids; snapping both to the coarser one removes that rounding, which is not a shape change.
    """

    def project(line: Polyline) -> NDArray[np.float64]:
        px = lonlat_to_px(np.asarray(line, dtype=np.float64))
        return np.round(px / grid_px) * grid_px if grid_px else px

    pts = [densify(project(line)) for line in lines if len(line) >= 2]
    if not pts:
        return np.zeros((0, 2))
    allp = np.concatenate(pts)
    x0, y0, x1, y1 = box_px
    keep = (allp[:, 0] >= x0) & (allp[:, 0] <= x1) & (allp[:, 1] >= y0) & (allp[:, 1] <= y1)
    return allp[keep]


def chamfer_px(a: NDArray[np.float64], b: NDArray[np.float64], dead_band_px: float = 0.0) -> float:
    """Symmetric mean nearest-point distance between two point sets, in reference pixels.

    With ``dead_band_px``, each distance counts only by how much it exceeds that (rounding noise is ignored).

    Zero for identical geometry, and it grows with how far the lines move (unlike a pixel XOR, which saturates
    as soon as a line moves by its own width), so consecutive morph steps can be compared with the whole range.
    """
    if len(a) == 0 or len(b) == 0:
        return math.inf if len(a) != len(b) else 0.0
    d_ab, _ = cKDTree(b).query(a)
    d_ba, _ = cKDTree(a).query(b)
    d_ab = np.maximum(d_ab - dead_band_px, 0.0)
    d_ba = np.maximum(d_ba - dead_band_px, 0.0)
    return float((d_ab.mean() + d_ba.mean()) / 2.0)
