"""Writing synthetic DEMs as GeoTIFFs, shared by the DEM reader tests and the unseen-terrain tests.

A plain module (not conftest.py) so test modules can import it by name: ``from synthetic_rasters import ...``.
"""

from __future__ import annotations

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
