"""What a tile request is checked against and what it returns: the tile grid options, the request checks, the
scale a tile is drawn at, and the rendered result."""

from __future__ import annotations

from dataclasses import dataclass

from engine.build.labels import DEFAULT_MAX_ZOOM
from engine.checks import check_method, check_t
from engine.tiles.grid import Tile, check_fractional_zoom, check_tile, tile_center_latitude
from engine.tiles.scale import scale_for_zoom

#: Latitude the scale of a tile is taken at, at most (Web Mercator's edge).
MAX_LATITUDE = 85.05


@dataclass(frozen=True)
class TileOptions:
    """How tiles are cut: grid size, buffer (grid units), layer name, served zoom range, and whether tiles
    where plain rounding makes lines cross are snap-rounded (always, but for tests that show what it guards)."""

    extent: int = 4096
    buffer_px: int = 64
    layer: str = "contours"
    min_zoom: int = 0
    max_zoom: int = DEFAULT_MAX_ZOOM
    snap_rounding: bool = True


@dataclass(frozen=True)
class TileResult:
    """A rendered tile: MVT bytes (None when it has no feature), the zoom and scale it was drawn at."""

    data: bytes | None
    features: int
    zoom: float
    scale: float


def tile_latitude(tile: Tile) -> float:
    """Latitude of the tile's centre, kept inside Web Mercator."""
    return max(-MAX_LATITUDE, min(MAX_LATITUDE, tile_center_latitude(tile)))


def scale_of_tile(tile: Tile, zoom: float) -> float:
    """Scale denominator a tile is drawn at: fractional ``zoom`` at the latitude of the tile's centre."""
    return float(scale_for_zoom(zoom, tile_latitude(tile)))


def check_tile_request(
    options: TileOptions, z: int, x: int, y: int, zoom: float | None, method: str, t: float | None
) -> tuple[Tile, float, float | None]:
    """Validate a tile request without rendering it (raises TileOutOfRange / InvalidParameter)."""
    tile = check_tile(z, x, y, options.min_zoom, options.max_zoom)
    zoomf = check_fractional_zoom(z, zoom)
    check_method(method)
    return tile, zoomf, check_t(t)
