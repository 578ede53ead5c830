"""Writing synthetic DEMs as GeoTIFFs, shared by the DEM reader tests and the unseen-terrain tests.

A plain module (not conftest.py) so test modules can import it by name: ``from synthetic_rasters import ...``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import rasterio


def write_geotiff(
    path: Path,
    z: np.ndarray,
    *,
    west: float,
    north: float,
    cell: float,
    crs: str | None,
    nodata: float | None = None,
    north_up: bool = True,
) -> Path:
    """Write ``z`` (rows, cols) as a one-band GeoTIFF whose grid starts at (``west``, ``north``) with square
    cells of ``cell`` CRS units; ``north_up=False`` stores row 0 at the southern edge instead."""
    transform = rasterio.Affine(cell, 0.0, west, 0.0, -cell, north)
    if not north_up:
        transform = rasterio.Affine(cell, 0.0, west, 0.0, cell, north - cell * z.shape[0])
    profile = {
        "driver": "GTiff",
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": z.dtype.name,
        "transform": transform,
        "nodata": nodata,
    }
    if crs is not None:
        profile["crs"] = crs
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(z, 1)
    return path


def fractal_heights(seed: int, beta: float, n: int = 128, relief_m: float = 400.0) -> np.ndarray:
    """(n, n) heights with a 1 / k^beta power spectrum, rounded to whole metres."""
    rng = np.random.default_rng(seed)
    k = np.hypot(np.fft.fftfreq(n)[:, None], np.fft.rfftfreq(n)[None, :])
    k[0, 0] = 1.0
    spectrum = (rng.standard_normal(k.shape) + 1j * rng.standard_normal(k.shape)) * k ** (-beta / 2)
    spectrum[0, 0] = 0.0
    z = np.fft.irfft2(spectrum, s=(n, n))
    return np.round(200.0 + (z - z.min()) / np.ptp(z) * relief_m)


def exact_level_contours(z: np.ndarray, interval: float) -> list[tuple[float, np.ndarray, bool]]:
    """Contour an integer DEM the way GDAL's ``gdal_contour`` does: at the levels themselves, no offset.

    Cells exactly at a level put contour vertices on grid nodes, so where two lines of one level meet at a
    saddle node they share that vertex and touch, as GDAL's output does. Returns (level, (n, 2) points in
    (column, row) grid units, closed) per line; a ring is given without its repeated last point.
    """
    import contourpy

    generator = contourpy.contour_generator(z=z, name="serial", line_type=contourpy.LineType.Separate)
    lines = []
    for level in np.arange(np.ceil(z.min() / interval), np.floor(z.max() / interval) + 1) * interval:
        for xy in generator.lines(float(level)):
            closed = len(xy) > 3 and bool(np.all(xy[0] == xy[-1]))
            pts = xy[:-1] if closed else xy
            keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])  # no repeated vertices
            pts = pts[keep]
            if len(pts) >= (3 if closed else 2):
                lines.append((float(level), pts, closed))
    return lines


def write_exact_level_geojson(
    path: Path, z: np.ndarray, interval: float, *, west: float, north: float, cell_deg: float
) -> Path:
    """Contours of ``z`` at exact levels (:func:`exact_level_contours`) as a GeoJSON file in lon/lat, with
    ``ele``: data like GDAL's, with lines of one level touching at saddles."""

    def lonlat(pts: np.ndarray) -> np.ndarray:
        return np.column_stack([west + pts[:, 0] * cell_deg, north - pts[:, 1] * cell_deg])

    return write_exact_level_lines(path, z, interval, lonlat)


def write_exact_level_lines(
    path: Path, z: np.ndarray, interval: float, to_xy: Callable[[np.ndarray], np.ndarray], crs: str | None = None
) -> Path:
    """Contours of ``z`` at exact levels as a GeoJSON file with ``ele``, as ``gdal_contour`` writes them:
    ``to_xy`` maps (n, 2) grid points (column, row) to coordinates in ``crs`` (None: lon/lat, RFC 7946), which
    is then named in a ``crs`` member."""
    import json

    features = []
    for k, (level, pts, closed) in enumerate(exact_level_contours(z, interval)):
        xy = to_xy(pts)
        if closed:
            xy = np.vstack([xy, xy[:1]])
        features.append(
            {
                "type": "Feature",
                "id": k,
                "properties": {"ele": level},
                "geometry": {"type": "LineString", "coordinates": xy.tolist()},
            }
        )
    collection: dict = {"type": "FeatureCollection", "features": features}
    if crs is not None:
        collection["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(collection))
    return path
