"""``--bbox`` and ``--dem-zoom``: the options of a terrain tile pyramid or a remote or cropped raster source,
and how a SOURCE argument becomes a source (fetching a pyramid's tiles first, with a progress bar)."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from engine.errors import InvalidParameter

if TYPE_CHECKING:
    from engine.io.source import Source

BboxOption = Annotated[
    str | None,
    typer.Option(
        "--bbox",
        help="Area W,S,E,N in degrees: required for a tile source (ENCODING:LOCATION); for a GeoTIFF (a file or "
        "an https:// URL), read only that part.",
        metavar="W,S,E,N",
    ),
]
DemZoomOption = Annotated[
    int | None,
    typer.Option(
        "--dem-zoom",
        min=0,
        max=24,
        help="Zoom of the tile source to read [the zoom whose pixel at the area's latitude is nearest to 0.28 mm at "
        "--source-scale: z13 at 1:50,000 in mid latitudes for 256 px tiles].",
    ),
]

#: What the SOURCE argument of a command that builds may be, for its help text.
SOURCE_HELP = (
    "Contour file (GeoJSON, GeoPackage, Shapefile), DEM (GeoTIFF, .asc, .npz), GeoTIFF URL (https://.../dem.tif), "
    "or terrain tiles ENCODING:LOCATION (terrarium:, mapbox:, custom:BASE:SCALE: a {z}/{x}/{y} URL or folder "
    "template, .pmtiles or .mbtiles; with --bbox)."
)


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    """``W,S,E,N`` as four numbers, or None.

    Raises
    ------
    InvalidParameter
        Not four finite numbers.
    """
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise InvalidParameter(f"--bbox {text!r}: expected W,S,E,N, four numbers in degrees")
    return values  # type: ignore[return-value]


def default_tile_cache() -> Path:
    """Where fetched terrain tiles are kept between runs ($XDG_CACHE_HOME/ccsm/tiles)."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ccsm" / "tiles"


def names_a_source(text: str) -> bool:
    """True when ``text`` is a file, a URL or a tile source rather than a dataset id."""
    if Path(text).is_file() or text.startswith(("http://", "https://")):
        return True
    if ":" not in text:  # a tile source names its encoding before a colon: a dataset id is told without the
        return False  # tile reader's imports (PIL, rasterio), a fifth of a second of every export's start
    from engine.io.terrain_tiles import looks_like_encoding

    return looks_like_encoding(text) is not None


def open_source(text: str, bbox: str | None, dem_zoom: int | None, source_scale: float) -> Source:
    """The source ``text`` names (:func:`engine.io.source.parse_source`); a tile pyramid's tiles are fetched
    here, with a progress bar, into the tile cache the build then reads them from.

    Raises
    ------
    CCSMError
        A bad source, area or zoom, or a tile that cannot be had (the message names it).
    """
    from rich.console import Console

    from app.cli.lazy_progress import progress_bar
    from engine.io.source import parse_source
    from engine.io.terrain_tiles import TerrainTiles, prefetch
    from engine.io.tile_fetch import TileCache

    source = parse_source(
        text,
        bbox=parse_bbox(bbox),
        dem_zoom=dem_zoom,
        source_scale=source_scale,
        tile_cache=TileCache(default_tile_cache()),
    )
    if isinstance(source, TerrainTiles):
        console = Console(stderr=True)
        with progress_bar(console) as progress:
            task = progress.add_task("fetching tiles", total=None)
            mosaic = prefetch(source, progress=lambda d, t: progress.update(task, completed=d, total=t))
        console.print(
            f"{source.name}: zoom {mosaic.zoom}, {mosaic.cols} x {mosaic.rows} pixels of {mosaic.pixel_size():.2f} m "
            "(Web Mercator)",
            highlight=False,
            soft_wrap=True,
        )
    return source
