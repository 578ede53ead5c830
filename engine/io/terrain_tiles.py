"""Terrain tile pyramids as a DEM: their encodings, how a source is written, and the Web Mercator grid they form.

A source is written ``ENCODING:LOCATION`` (docs/cli.md, "Terrain tiles"):

- ENCODING is ``terrarium`` (h = R·256 + G + B/256 − 32768), ``mapbox`` (terrain-RGB:
  h = −10000 + (R·65536 + G·256 + B)·0.1) or ``custom:BASE:SCALE`` (h = BASE + (R·65536 + G·256 + B)·SCALE).
  Both named encodings are that same formula: Terrarium is BASE −32768, SCALE 1/256.
- LOCATION is a URL template (``https://host/{z}/{x}/{y}.png``, ``.webp``), a local folder template
  (``/path/{z}/{x}/{y}.png`` or ``file:///path/...``), or a raster PMTiles (local or over HTTP) or MBTiles file.

The tiles of one zoom over an area (``bbox`` in degrees) form one grid of heights in Web Mercator
(:class:`TileMosaic`); it is read window by window (:mod:`engine.io.dem_windows`) exactly as a GeoTIFF is, so
only the tiles of one window are decoded at a time.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError
from rasterio.windows import Window

from engine.errors import InvalidParameter, SourceError
from engine.io.crs import WEB_MERCATOR
from engine.io.dem_windows import RasterHeader
from engine.io.tile_fetch import TileCache, TileRef, describe_tile, fetch_tiles, open_tile_reader

#: Half the side of the Web Mercator square (metres): the world spans ±this in x and y.
MERCATOR_HALF_SIDE = 20037508.342789244

#: Web Mercator reaches this latitude (degrees); the square's corners.
MERCATOR_MAX_LAT = 85.0511287798066

#: The OGC standard display pixel (metres), as in :mod:`engine.tiles.scale`: the DEM zoom's default rule.
OGC_PIXEL_M = 0.00028

#: Tile side assumed when choosing the default zoom; a 512 px pyramid is then read one zoom lower.
ASSUMED_TILE_PX = 256

#: Zooms a pyramid may have.
MAX_ZOOM = 24

#: More tiles than this over the area means the zoom is wrong for it (a continent at z14): refuse.
MAX_TILES = 40_000


@dataclass(frozen=True)
class TileEncoding:
    """How a tile's colour holds a height: h = base + (R·65536 + G·256 + B)·scale."""

    name: str
    base: float
    scale: float

    def decode(self, rgb: NDArray[np.uint8]) -> NDArray[np.float64]:
        """Heights of an (rows, cols, 3) uint8 image."""
        code = (rgb[..., 0].astype(np.float64) * 65536.0) + rgb[..., 1].astype(np.float64) * 256.0 + rgb[..., 2]
        return self.base + code * self.scale

    def encode(self, heights: NDArray[np.float64]) -> NDArray[np.uint8]:
        """The (rows, cols, 3) uint8 image of heights, each rounded to the nearest step of the encoding.

        Raises
        ------
        InvalidParameter
            A height the encoding cannot hold (below ``base`` or above ``base + (2^24 − 1)·scale``).
        """
        code = np.rint((np.asarray(heights, dtype=np.float64) - self.base) / self.scale)
        if not np.all(np.isfinite(code)) or code.min(initial=0) < 0 or code.max(initial=0) > 2**24 - 1:
            raise InvalidParameter(f"heights outside what the {self.name} encoding holds")
        code = code.astype(np.int64)
        rgb = np.stack([(code >> 16) & 255, (code >> 8) & 255, code & 255], axis=-1)
        return rgb.astype(np.uint8)


#: The encodings known by name.
ENCODINGS: dict[str, TileEncoding] = {
    "terrarium": TileEncoding("terrarium", -32768.0, 1.0 / 256.0),
    "mapbox": TileEncoding("mapbox", -10000.0, 0.1),
}

#: How an encoding is written, for messages.
ENCODING_SYNTAX = "terrarium, mapbox or custom:BASE:SCALE"


@dataclass(frozen=True)
class TerrainTiles:
    """A terrain tile pyramid read as a DEM over an area at one zoom.

    Attributes
    ----------
    encoding
        How a colour holds a height.
    location
        URL template, folder template, or PMTiles / MBTiles file (see the module's docstring).
    bbox
        (west, south, east, north) in degrees.
    zoom
        The pyramid's zoom to read; None = :func:`default_zoom` at ``source_scale``.
    source_scale
        The scale denominator the default zoom matches.
    cache
        Where fetched tiles are kept (not part of what the source is).
    """

    encoding: TileEncoding
    location: str
    bbox: tuple[float, float, float, float]
    zoom: int | None = None
    source_scale: float = 50_000.0
    cache: TileCache = field(default_factory=TileCache, compare=False, repr=False)

    @property
    def name(self) -> str:
        """A short name for messages and the stored dataset's source."""
        return f"{self.encoding.name}:{self.location}"

    @property
    def stem(self) -> str:
        """A name for a dataset id: the location's last part that is not a template field."""
        parts = [p for p in self.location.replace("\\", "/").split("/") if p and "{" not in p and ":" not in p]
        stem = Path(parts[-1]).stem if parts else "tiles"
        return f"{stem}-z{self.zoom}" if self.zoom is not None else stem

    def identity(self) -> str:
        """What the source is, as a build's content hash takes it (the tiles are taken as unchanging)."""
        e = self.encoding
        zoom = self.zoom if self.zoom is not None else f"default at 1:{self.source_scale:g}"
        return f"terrain-tiles {e.base!r} {e.scale!r} {self.location} {self.bbox!r} z{zoom}"


def parse_encoding(text: str) -> tuple[TileEncoding, str] | None:
    """Split ``ENCODING:LOCATION`` into the encoding and the location; None when ``text`` names no encoding
    (a plain path or URL).

    Raises
    ------
    SourceError
        ``custom:`` without a numeric base and a positive scale.

    >>> parse_encoding("mapbox:tiles.mbtiles")[0].base
    -10000.0
    >>> parse_encoding("custom:-100:0.01:/t/{z}/{x}/{y}.png")
    (TileEncoding(name='custom', base=-100.0, scale=0.01), '/t/{z}/{x}/{y}.png')
    """
    head, sep, rest = text.partition(":")
    if not sep:
        return None
    key = head.strip().lower()
    if key in ENCODINGS:
        return ENCODINGS[key], rest
    if key != "custom":
        return None
    parts = rest.split(":", 2)
    try:
        base, scale = float(parts[0]), float(parts[1])
        location = parts[2]
    except (IndexError, ValueError):
        raise SourceError(f"{text!r}: a custom encoding is written custom:BASE:SCALE:LOCATION") from None
    if not (math.isfinite(base) and math.isfinite(scale) and scale > 0):
        raise SourceError(f"{text!r}: custom BASE must be a number and SCALE a positive number")
    return TileEncoding("custom", base, scale), location


def looks_like_encoding(text: str) -> str | None:
    """The word before the first ``:`` when it could only be meant as an encoding (not a URL scheme, a
    drive letter or part of a path), else None: an unknown one is then named in the error."""
    head, sep, _ = text.partition(":")
    if not sep or len(head) < 2 or not head.isalnum() or head.lower() in ("http", "https", "file", "s3", "gs"):
        return None
    return head


def check_bbox(bbox: tuple[float, float, float, float] | None, where: str) -> tuple[float, float, float, float]:
    """A (west, south, east, north) area in degrees, checked.

    Raises
    ------
    InvalidParameter
        No area, or one that is not finite, inverted, or beyond the poles or the antimeridian.
    """
    if bbox is None:
        raise InvalidParameter(f"{where}: a terrain tile source needs an area (--bbox W,S,E,N in degrees)")
    west, south, east, north = (float(v) for v in bbox)
    if not all(math.isfinite(v) for v in (west, south, east, north)):
        raise InvalidParameter(f"bbox {bbox}: not finite numbers")
    if not (-180.0 <= west < east <= 180.0 and -90.0 <= south < north <= 90.0):
        raise InvalidParameter(
            f"bbox {bbox}: expected W,S,E,N degrees with W < E in [-180, 180] and S < N in [-90, 90]"
        )
    return west, south, east, north


def default_zoom(source_scale: float, bbox: tuple[float, float, float, float], tile_px: int = ASSUMED_TILE_PX) -> int:
    """The zoom whose pixel at the area's centre latitude is nearest (in ratio) to one OGC display pixel
    (0.28 mm) at ``source_scale``: the DEM's ground resolution then matches the map's at the source scale
    (14 m at 1:50,000), as :mod:`engine.tiles.scale` relates zoom and scale.

    >>> default_zoom(50_000, (174.7, -36.9, 174.8, -36.8))
    13
    """
    lat = max(-MERCATOR_MAX_LAT, min(MERCATOR_MAX_LAT, (bbox[1] + bbox[3]) / 2.0))
    ground_at_z0 = 2.0 * MERCATOR_HALF_SIDE * math.cos(math.radians(lat)) / tile_px
    wanted = source_scale * OGC_PIXEL_M
    return int(min(MAX_ZOOM, max(0, round(math.log2(ground_at_z0 / wanted)))))


def lonlat_to_mercator(lon: float, lat: float) -> tuple[float, float]:
    """Web Mercator metres of a longitude and latitude (latitude clamped to Mercator's square)."""
    lat = max(-MERCATOR_MAX_LAT, min(MERCATOR_MAX_LAT, lat))
    x = math.radians(lon) * MERCATOR_HALF_SIDE / math.pi
    y = math.log(math.tan(math.pi / 4.0 + math.radians(lat) / 2.0)) * MERCATOR_HALF_SIDE / math.pi
    return x, y


@dataclass(frozen=True)
class TileMosaic:
    """The pixels of a tile pyramid's zoom over an area, as one raster in Web Mercator: what
    :mod:`engine.io.dem_windows` reads window by window. Plain data, so a worker process can read its windows.

    ``col0``, ``row0`` are the area's first pixel in the zoom's whole grid; pixel edges are those of the tiles.
    """

    source: TerrainTiles
    zoom: int
    tile_px: int
    col0: int
    row0: int
    cols: int
    rows: int

    @property
    def name(self) -> str:
        """The source's name, for messages."""
        return self.source.name

    def header(self) -> RasterHeader:
        """The area's size, geotransform and CRS."""
        res = self.pixel_size()
        transform = (res, 0.0, -MERCATOR_HALF_SIDE + self.col0 * res, 0.0, -res, MERCATOR_HALF_SIDE - self.row0 * res)
        wkt = _web_mercator_wkt()
        return RasterHeader(self.rows, self.cols, transform, wkt, (self.tile_px, self.tile_px))

    def pixel_size(self) -> float:
        """Metres of Web Mercator per pixel."""
        return 2.0 * MERCATOR_HALF_SIDE / (self.tile_px * 2**self.zoom)

    def read(self, window: Window) -> np.ma.MaskedArray:
        """Heights of a window of the area (float64; masked where a tile's alpha is 0).

        Raises
        ------
        SourceError
            A tile is missing, unreadable or not an image of the pyramid's size (the error names it).
        """
        c0, r0 = self.col0 + int(window.col_off), self.row0 + int(window.row_off)
        c1, r1 = c0 + int(window.width), r0 + int(window.height)  # exclusive
        t = self.tile_px
        refs = [
            TileRef(self.zoom, tx, ty)
            for ty in range(r0 // t, (r1 - 1) // t + 1)
            for tx in range(c0 // t, (c1 - 1) // t + 1)
        ]
        reader = open_tile_reader(self.source.location)
        data = fetch_tiles(reader, refs, cache=self.source.cache)
        z = np.ma.masked_all((r1 - r0, c1 - c0), dtype=np.float64)
        for ref in refs:
            heights = decode_tile(data[ref], self.source.encoding, t, describe_tile(reader, ref))
            # The part of this tile inside the window, in the tile's and in the window's pixels.
            tc0, tr0 = ref.x * t, ref.y * t
            a0, a1 = max(c0, tc0), min(c1, tc0 + t)
            b0, b1 = max(r0, tr0), min(r1, tr0 + t)
            z[b0 - r0 : b1 - r0, a0 - c0 : a1 - c0] = heights[b0 - tr0 : b1 - tr0, a0 - tc0 : a1 - tc0]
        return np.ma.masked_invalid(z)


def decode_tile(data: bytes, encoding: TileEncoding, tile_px: int | None, where: str) -> np.ma.MaskedArray:
    """Heights of one tile's image bytes (PNG, WebP, ...: what Pillow reads), masked where alpha is 0.

    Raises
    ------
    SourceError
        Not an image, or not ``tile_px`` pixels square (None: any square).
    """
    try:
        with Image.open(io.BytesIO(data)) as image:
            image.load()
            rgba = np.asarray(image.convert("RGBA"))
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise SourceError(f"tile {where}: not an image ({len(data)} bytes: {_head(data)}) ({exc})") from exc
    rows, cols = rgba.shape[:2]
    if rows != cols or (tile_px is not None and rows != tile_px):
        want = f"{tile_px} x {tile_px}" if tile_px is not None else "square"
        raise SourceError(f"tile {where}: {cols} x {rows} pixels, expected {want}")
    heights = encoding.decode(rgba[..., :3])
    return np.ma.masked_array(heights, mask=rgba[..., 3] == 0)


def _head(data: bytes) -> str:
    return repr(data[:24])


def open_mosaic(source: TerrainTiles) -> TileMosaic:
    """The grid of ``source``'s area at its zoom (the default zoom at its source scale when it names none).

    The first tile is read to learn the pyramid's tile size (a 512 px pyramid's default zoom is one lower).

    Raises
    ------
    InvalidParameter
        No or a bad area, a bad zoom, or more than :data:`MAX_TILES` tiles.
    SourceError
        The first tile cannot be read (the error names it).
    """
    bbox = check_bbox(source.bbox, source.name)
    zoom = source.zoom
    if zoom is None:
        zoom = default_zoom(source.source_scale, bbox)
    if not 0 <= zoom <= MAX_ZOOM:
        raise InvalidParameter(f"DEM zoom {zoom} must be in 0..{MAX_ZOOM}")
    first = _area_tiles(bbox, zoom, ASSUMED_TILE_PX)[0]
    reader = open_tile_reader(source.location)
    try:
        data = fetch_tiles(reader, [first], cache=source.cache)[first]
    except SourceError as exc:
        raise SourceError(f"{exc} (the first tile of bbox {bbox} at zoom {zoom}: does the pyramid cover it?)") from exc
    tile_px = decode_tile(data, source.encoding, None, describe_tile(reader, first)).shape[0]
    if tile_px != ASSUMED_TILE_PX and source.zoom is None:
        zoom = max(0, zoom - round(math.log2(tile_px / ASSUMED_TILE_PX)))  # the same ground resolution
    return _mosaic(source, bbox, zoom, tile_px)


def _mosaic(source: TerrainTiles, bbox: tuple[float, float, float, float], zoom: int, tile_px: int) -> TileMosaic:
    """The pixels of the zoom's grid that the area touches (edges outward to whole pixels)."""
    x_w, y_s = lonlat_to_mercator(bbox[0], bbox[1])
    x_e, y_n = lonlat_to_mercator(bbox[2], bbox[3])
    res = 2.0 * MERCATOR_HALF_SIDE / (tile_px * 2**zoom)
    side = tile_px * 2**zoom
    c0 = max(0, math.floor((x_w + MERCATOR_HALF_SIDE) / res))
    c1 = min(side, math.ceil((x_e + MERCATOR_HALF_SIDE) / res))
    r0 = max(0, math.floor((MERCATOR_HALF_SIDE - y_n) / res))
    r1 = min(side, math.ceil((MERCATOR_HALF_SIDE - y_s) / res))
    if c1 - c0 < 2 or r1 - r0 < 2:
        raise InvalidParameter(
            f"bbox {bbox} covers {c1 - c0} x {r1 - r0} pixels at zoom {zoom}; a DEM needs at least 2 x 2 "
            "(a larger area or --dem-zoom)"
        )
    n_tiles = ((c1 - 1) // tile_px - c0 // tile_px + 1) * ((r1 - 1) // tile_px - r0 // tile_px + 1)
    if n_tiles > MAX_TILES:
        raise InvalidParameter(
            f"bbox {bbox} at zoom {zoom} needs {n_tiles} tiles (more than {MAX_TILES}): a smaller area or a "
            "lower --dem-zoom"
        )
    return TileMosaic(source, zoom, tile_px, c0, r0, c1 - c0, r1 - r0)


def _area_tiles(bbox: tuple[float, float, float, float], zoom: int, tile_px: int) -> list[TileRef]:
    """The tiles of a zoom that an area touches, row by row."""
    n = 2**zoom
    x_w, y_s = lonlat_to_mercator(bbox[0], bbox[1])
    x_e, y_n = lonlat_to_mercator(bbox[2], bbox[3])
    span = 2.0 * MERCATOR_HALF_SIDE / n
    tx0, tx1 = (min(n - 1, max(0, math.floor((x + MERCATOR_HALF_SIDE) / span))) for x in (x_w, x_e))
    ty0, ty1 = (min(n - 1, max(0, math.floor((MERCATOR_HALF_SIDE - y) / span))) for y in (y_n, y_s))
    return [TileRef(zoom, x, y) for y in range(ty0, ty1 + 1) for x in range(tx0, tx1 + 1)]


def mosaic_tiles(mosaic: TileMosaic) -> list[TileRef]:
    """Every tile of a mosaic, row by row."""
    t = mosaic.tile_px
    return [
        TileRef(mosaic.zoom, x, y)
        for y in range(mosaic.row0 // t, (mosaic.row0 + mosaic.rows - 1) // t + 1)
        for x in range(mosaic.col0 // t, (mosaic.col0 + mosaic.cols - 1) // t + 1)
    ]


def _web_mercator_wkt() -> str:
    from engine.io.crs import parse_crs

    return str(parse_crs(WEB_MERCATOR).to_wkt())


def prefetch(source: TerrainTiles, *, progress: Callable[[int, int], None] | None = None) -> TileMosaic:
    """Fetch every tile of the source's area into its cache (concurrently, with retries), so that a build
    reads them from there; the mosaic they form.

    Raises
    ------
    SourceError, InvalidParameter
        As :func:`open_mosaic`, and the first tile that cannot be had.
    """
    mosaic = open_mosaic(source)
    fetch_tiles(open_tile_reader(source.location), mosaic_tiles(mosaic), cache=source.cache, progress=progress)
    source.cache.trim()
    return mosaic
