"""A raster DEM read window by window from a local file or a URL, whole or over an area.

A URL (``https://host/dem.tif``, a Cloud-Optimized GeoTIFF) is read through GDAL's ``/vsicurl/`` with HTTP
range requests: each window asks for the bytes of the internal tiles it covers, and nothing is downloaded
whole. GDAL is told not to list the server's folder (``GDAL_DISABLE_READDIR_ON_OPEN``) and to range-read only
GeoTIFF names (``CPL_VSIL_CURL_ALLOWED_EXTENSIONS``), the two settings that otherwise cost a request per
sidecar file it looks for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import rasterio
from rasterio.errors import RasterioError
from rasterio.warp import transform_bounds
from rasterio.windows import Window, from_bounds

from engine.errors import InvalidParameter, SourceError
from engine.io.crs import WGS84
from engine.io.dem_windows import RasterHeader

#: File names GDAL's HTTP reader may open.
REMOTE_SUFFIXES: tuple[str, ...] = (".tif", ".tiff")

#: GDAL settings of every read of a URL (see the module's docstring).
GDAL_HTTP_CONFIG: dict[str, str] = {
    "GDAL_DISABLE_READDIR_ON_OPEN": "EMPTY_DIR",
    "CPL_VSIL_CURL_ALLOWED_EXTENSIONS": ",".join(REMOTE_SUFFIXES),
    "GDAL_HTTP_MAX_RETRY": "3",
    "GDAL_HTTP_RETRY_DELAY": "0.5",
    "GDAL_HTTP_TIMEOUT": "30",
    "GDAL_HTTP_MERGE_CONSECUTIVE_RANGES": "YES",
    "GDAL_HTTP_MULTIPLEX": "YES",
}


def is_url(location: str) -> bool:
    """True for an ``http://`` or ``https://`` location."""
    return location.startswith(("http://", "https://"))


@dataclass(frozen=True)
class RasterDem:
    """A raster DEM (a local file or a URL), the whole of it or the pixels an area in degrees touches.

    Attributes
    ----------
    location
        A path or an ``http(s)://`` URL of a GeoTIFF.
    bbox
        (west, south, east, north) in degrees, or None for the whole raster.
    """

    location: str
    bbox: tuple[float, float, float, float] | None = None

    @property
    def name(self) -> str:
        """The file name, for messages and the stored dataset's source."""
        return Path(urlparse(self.location).path).name if is_url(self.location) else Path(self.location).name

    @property
    def stem(self) -> str:
        """The file name without its extension."""
        return Path(self.name).stem

    def identity(self) -> str:
        """What the source is, as a build's content hash takes it (a URL's bytes are taken as unchanging)."""
        return f"raster {self.location} {self.bbox!r}"

    def _gdal_path(self) -> str:
        return f"/vsicurl/{self.location}" if is_url(self.location) else self.location

    def _env(self) -> rasterio.Env:
        return rasterio.Env(**GDAL_HTTP_CONFIG) if is_url(self.location) else rasterio.Env()

    def header(self) -> RasterHeader:
        """Size, geotransform, CRS and internal tiling of the raster, or of its part the area touches.

        Raises
        ------
        SourceError
            Unreadable or unreachable, no CRS.
        InvalidParameter
            The area touches fewer than 2 x 2 pixels of the raster.
        """
        try:
            with self._env(), rasterio.open(self._gdal_path()) as src:
                if src.crs is None:
                    raise SourceError(f"{self.location}: the DEM has no CRS")
                area = self._area(src)
                t = src.window_transform(area)
                tiled = bool(src.profile.get("tiled", False))
                return RasterHeader(
                    rows=int(area.height),
                    cols=int(area.width),
                    transform=(t.a, t.b, t.c, t.d, t.e, t.f),
                    crs_wkt=src.crs.to_wkt(),
                    tile_shape=tuple(src.block_shapes[0]) if tiled else None,  # type: ignore[arg-type]
                )
        except RasterioError as exc:
            raise SourceError(f"{self.location}: cannot read DEM ({exc})") from exc

    def _area(self, src: rasterio.DatasetReader) -> Window:
        """The pixels the area touches (edges outward to whole pixels), or the whole raster."""
        if self.bbox is None:
            return Window(0, 0, src.width, src.height)
        bounds = transform_bounds(WGS84, src.crs, *self.bbox, densify_pts=21)
        w = from_bounds(*bounds, transform=src.transform)
        c0, r0 = max(0, math.floor(w.col_off)), max(0, math.floor(w.row_off))
        c1 = min(src.width, math.ceil(w.col_off + w.width))
        r1 = min(src.height, math.ceil(w.row_off + w.height))
        if c1 - c0 < 2 or r1 - r0 < 2:
            raise InvalidParameter(
                f"bbox {self.bbox} covers {max(0, c1 - c0)} x {max(0, r1 - r0)} pixels of {self.name}; a DEM needs "
                "at least 2 x 2"
            )
        return Window(c0, r0, c1 - c0, r1 - r0)

    def read(self, window: Window) -> np.ma.MaskedArray:
        """The heights of a window of the area (float64, masked where there is no data).

        Raises
        ------
        SourceError
            Unreadable or unreachable.
        """
        try:
            with self._env(), rasterio.open(self._gdal_path()) as src:
                area = self._area(src)
                col, row = area.col_off + window.col_off, area.row_off + window.row_off
                shifted = Window(col, row, window.width, window.height)
                return np.ma.masked_invalid(src.read(1, window=shifted, masked=True).astype(np.float64))
        except RasterioError as exc:
            raise SourceError(f"{self.location}: cannot read window {window} ({exc})") from exc
