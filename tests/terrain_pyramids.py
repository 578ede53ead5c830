"""Terrain tile pyramids and COGs made by the tests from a real DEM: the DEM reprojected to Web Mercator on the
pixel grid of one zoom (rasterio.warp), written as a GeoTIFF and cut into encoded 256 px PNG tiles."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rasterio
from PIL import Image
from rasterio.warp import Resampling, reproject, transform_bounds

from engine.io.terrain_tiles import TileEncoding

HALF = 20037508.342789244
TILE = 256


@dataclass(frozen=True)
class Pyramid:
    """Tiles under ``root/{z}/{x}/{y}.png``, the GeoTIFF they were cut from, and the DEM's area in degrees."""

    root: Path
    geotiff: Path
    zoom: int
    bbox: tuple[float, float, float, float]
    tiles: list[tuple[int, int, int]]


def _tile_of(lon: float, lat: float, zoom: int) -> tuple[int, int]:
    n = 2**zoom
    x = (lon + 180.0) / 360.0 * n
    y = (1.0 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2.0 * n
    return int(x), int(y)


def write_pyramid(
    folder: Path,
    z: np.ndarray,
    transform: rasterio.Affine,
    crs: str,
    *,
    zoom: int,
    encoding: TileEncoding,
    on_step: bool = True,
) -> Pyramid:
    """Reproject (bilinear) the DEM ``z`` to the Web Mercator grid of the tiles at ``zoom`` that cover it, write
    that grid as ``folder/mercator.tif`` and its tiles as RGBA PNG (alpha 0 where the DEM has no data).
    ``on_step``: the GeoTIFF's heights rounded to the encoding's step first, so the tiles hold them exactly."""
    rows, cols = z.shape
    bounds = rasterio.transform.array_bounds(rows, cols, transform)
    west, south, east, north = transform_bounds(crs, "EPSG:4326", *bounds)
    tx0, ty0 = _tile_of(west, north, zoom)
    tx1, ty1 = _tile_of(east, south, zoom)
    res = 2 * HALF / (TILE * 2**zoom)
    dst_transform = rasterio.Affine(res, 0, -HALF + tx0 * TILE * res, 0, -res, HALF - ty0 * TILE * res)
    merc = np.full(((ty1 - ty0 + 1) * TILE, (tx1 - tx0 + 1) * TILE), np.nan)
    reproject(
        z.astype(np.float64), merc, src_transform=transform, src_crs=crs, dst_transform=dst_transform,
        dst_crs="EPSG:3857", resampling=Resampling.bilinear, src_nodata=np.nan, dst_nodata=np.nan,
    )
    if on_step:
        merc = encoding.base + np.rint((merc - encoding.base) / encoding.scale) * encoding.scale
    folder.mkdir(parents=True, exist_ok=True)
    geotiff = folder / "mercator.tif"
    with rasterio.open(
        geotiff, "w", driver="GTiff", height=merc.shape[0], width=merc.shape[1], count=1, dtype="float64",
        crs="EPSG:3857", transform=dst_transform, nodata=np.nan,
    ) as dst:
        dst.write(merc, 1)
    tiles = []
    for ty in range(ty0, ty1 + 1):
        for tx in range(tx0, tx1 + 1):
            block = merc[(ty - ty0) * TILE : (ty - ty0 + 1) * TILE, (tx - tx0) * TILE : (tx - tx0 + 1) * TILE]
            rgb = encoding.encode(np.nan_to_num(block, nan=0.0))
            alpha = np.where(np.isnan(block), 0, 255).astype(np.uint8)
            path = folder / "tiles" / str(zoom) / str(tx) / f"{ty}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.dstack([rgb, alpha]), "RGBA").save(path)
            tiles.append((zoom, tx, ty))
    return Pyramid(folder / "tiles", geotiff, zoom, (west, south, east, north), tiles)


def write_cog(path: Path, z: np.ndarray, transform: rasterio.Affine, crs: str) -> Path:
    """A Cloud-Optimized GeoTIFF (256 px internal tiles, deflate, overviews) of a DEM."""
    with rasterio.open(
        path, "w", driver="COG", height=z.shape[0], width=z.shape[1], count=1, dtype="float32", crs=crs,
        transform=transform, nodata=-9999.0, blocksize=256, compress="deflate",
    ) as dst:
        dst.write(z.astype(np.float32), 1)
    return path
