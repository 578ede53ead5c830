"""Input and output of the engine: one entry point for every source format, and GeoJSON output.

``read_source`` dispatches on the file's extension: contour lines (GeoJSON, GeoPackage, Shapefile) are read
as they are, a DEM (GeoTIFF, ESRI ASCII grid, ``.npz``) is contoured at ``interval``. Either way the result
is a :class:`~engine.types.ContourSet` in metres of a projected working CRS.

``parse_source`` turns what a user writes into a source: a path, a GeoTIFF URL (read by HTTP range requests,
:mod:`engine.io.raster_windows`) or a terrain tile pyramid written ``ENCODING:LOCATION``
(:mod:`engine.io.terrain_tiles`), with an area and a zoom.
"""

from __future__ import annotations

import os
from concurrent.futures import Executor
from pathlib import Path

from engine.errors import InvalidParameter, SourceError
from engine.io.crs import choose_working_crs, make_transformer
from engine.io.dem import DEM_SUFFIXES, RASTER_SUFFIXES, contours_from_dem
from engine.io.geojson_writer import write_geojson
from engine.io.raster_windows import REMOTE_SUFFIXES, RasterDem, is_url
from engine.io.sample import sample_contours_path, sample_dem_path
from engine.io.terrain_tiles import (
    ENCODING_SYNTAX,
    ENCODINGS,
    TerrainTiles,
    check_bbox,
    looks_like_encoding,
    parse_encoding,
)
from engine.io.tile_fetch import TileCache
from engine.io.vector_reader import VECTOR_SUFFIXES, read_contours
from engine.scratch import ReadScratch
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import ContourSet

__all__ = [
    "SUPPORTED_SUFFIXES",
    "Source",
    "parse_source",
    "choose_working_crs",
    "contours_from_dem",
    "make_transformer",
    "read_contours",
    "read_source",
    "sample_contours_path",
    "sample_dem_path",
    "write_geojson",
]

#: Every file extension :func:`read_source` understands.
SUPPORTED_SUFFIXES: tuple[str, ...] = VECTOR_SUFFIXES + DEM_SUFFIXES

#: A source as :func:`parse_source` gives it: a local file, a raster read in windows (a URL or an area of a
#: file), or a terrain tile pyramid's area.
Source = Path | RasterDem | TerrainTiles


def parse_source(
    text: str | os.PathLike[str],
    *,
    bbox: tuple[float, float, float, float] | None = None,
    dem_zoom: int | None = None,
    source_scale: float = 50_000.0,
    tile_cache: TileCache | None = None,
) -> Source:
    """The source a user wrote.

    Parameters
    ----------
    text
        A path; a GeoTIFF URL (``https://host/dem.tif``); or a terrain tile pyramid ``ENCODING:LOCATION``,
        ENCODING ``terrarium``, ``mapbox`` or ``custom:BASE:SCALE``, LOCATION a ``{z}/{x}/{y}`` URL or folder
        template or a ``.pmtiles`` / ``.mbtiles`` file (:mod:`engine.io.terrain_tiles`).
    bbox
        (west, south, east, north) in degrees: required for a tile pyramid; for a raster (a file or a URL),
        read only the pixels it touches.
    dem_zoom
        Tile pyramids only: the zoom to read; None = the zoom whose pixel matches ``source_scale``
        (:func:`engine.io.terrain_tiles.default_zoom`).
    tile_cache
        Where a pyramid's fetched tiles are kept (None: in memory only).

    Raises
    ------
    SourceError
        An unknown encoding, a URL that is neither a GeoTIFF nor a tile source.
    InvalidParameter
        A pyramid without an area, a bad area, an area or a zoom for a source that takes none.
    """
    raw = os.fspath(text)
    encoded = parse_encoding(raw)
    if encoded is not None and not Path(raw).exists():
        encoding, location = encoded
        return TerrainTiles(
            encoding,
            location,
            check_bbox(bbox, raw),
            dem_zoom,
            source_scale=source_scale,
            cache=tile_cache if tile_cache is not None else TileCache(),
        )
    if dem_zoom is not None:
        raise InvalidParameter(f"{raw}: --dem-zoom applies to terrain tile sources (ENCODING:LOCATION) only")
    unknown = looks_like_encoding(raw)
    if unknown is not None and not Path(raw).exists():
        raise SourceError(f"{raw}: unknown terrain tile encoding {unknown!r}; expected {ENCODING_SYNTAX}")
    if is_url(raw):
        if not raw.lower().split("?")[0].endswith(REMOTE_SUFFIXES):
            raise SourceError(
                f"{raw}: a URL source is a GeoTIFF ({', '.join(REMOTE_SUFFIXES)}) or a tile pyramid written "
                f"ENCODING:URL ({ENCODING_SYNTAX})"
            )
        return RasterDem(raw, None if bbox is None else check_bbox(bbox, raw))
    path = Path(raw).expanduser()
    if bbox is None:
        return path
    if path.suffix.lower() not in RASTER_SUFFIXES:
        raise InvalidParameter(f"{raw}: --bbox applies to rasters ({', '.join(RASTER_SUFFIXES)}) and tile sources")
    if not path.exists():
        raise SourceError(f"{path}: file not found")
    return RasterDem(str(path.resolve()), check_bbox(bbox, raw))


def takes_area(text: str) -> bool:
    """True when the source ``text`` names can be read over an area (``bbox``): a tile pyramid, a GeoTIFF URL
    or a raster file; a contour file or an ``.npz`` is always read whole."""
    if looks_like_encoding(text) is not None or is_url(text):
        return True
    return Path(text).suffix.lower() in RASTER_SUFFIXES


def source_arguments(source: Source) -> tuple[str, tuple[float, float, float, float] | None, int | None]:
    """What :func:`parse_source` takes to give ``source`` again: the text, the area and the DEM zoom (how a
    build process is told its source)."""
    if isinstance(source, TerrainTiles):
        e = source.encoding
        named = ENCODINGS.get(e.name)
        head = e.name if named == e else f"custom:{e.base!r}:{e.scale!r}"
        return f"{head}:{source.location}", source.bbox, source.zoom
    if isinstance(source, RasterDem):
        return source.location, source.bbox, None
    return str(source), None, None


def is_dem(source: Source) -> bool:
    """True when ``source`` is a DEM (a raster file, an ``.npz``, a raster URL or a tile pyramid), whose lines
    are traced as it is read; False for a contour file."""
    return not isinstance(source, Path) or source.suffix.lower() in DEM_SUFFIXES


def source_file(source: Source) -> Path | None:
    """The local file whose bytes a source is, or None (a URL or a tile pyramid)."""
    if isinstance(source, Path):
        return source
    if isinstance(source, RasterDem) and not is_url(source.location):
        return Path(source.location)
    return None


def read_source(
    path: str | os.PathLike[str] | RasterDem | TerrainTiles,
    *,
    elevation_field: str | None = None,
    layer: str | None = None,
    interval: float | None = None,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    block: int | None = None,
    executor: Executor | None = None,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """Read contours from a contour file or a DEM.

    Parameters
    ----------
    path
        ``.geojson`` / ``.json`` / ``.gpkg`` / ``.shp``: contour lines with an elevation attribute.
        ``.tif`` / ``.tiff`` / ``.asc`` / ``.npz``: a DEM, contoured at every multiple of ``interval``.
        A :class:`~engine.io.raster_windows.RasterDem` or :class:`~engine.io.terrain_tiles.TerrainTiles`
        (see :func:`parse_source`): a DEM read window by window.
    elevation_field
        Contour files only: the elevation attribute (found by name when None, see
        :func:`engine.io.vector_reader.read_contours`).
    layer
        Contour files only: layer of a multi-layer file.
    interval
        Contour interval in the data's vertical unit. Required for a DEM; for a contour file it is recorded
        as given, or inferred from the elevations when None.
    tolerances
        Distances in metres below which vertices merge and lines count as empty.
    block, executor
        DEMs only: the window side and where windows are traced (see
        :func:`engine.io.dem.contours_from_dem`).
    scratch
        Where what is read waits, in a scratch file rather than in memory (:mod:`engine.scratch`): a DEM
        is then held one level at a time, and the set's ``contours`` are read from the file when asked (it
        must stay open while they are used). None = everything in memory.

    Returns
    -------
    ContourSet
        Coordinates in metres of ``working_crs``; unusable features listed in ``bad_features``.

    Raises
    ------
    SourceError
        Missing or unreadable file, unknown format, missing or unknown CRS, missing elevation field,
        nothing usable.
    InvalidParameter
        A DEM without a positive ``interval``.

    Examples
    --------
    >>> cs = read_source(sample_contours_path())
    >>> cs.working_crs, len(cs.contours)
    ('EPSG:32616', 1830)
    """
    dem: Path | RasterDem | TerrainTiles
    if isinstance(path, (RasterDem, TerrainTiles)):
        dem, name = path, path.name
    else:
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix in VECTOR_SUFFIXES:
            contour_set = read_contours(
                path, elevation_field=elevation_field, layer=layer, tolerances=tolerances, scratch=scratch
            )
            if interval is not None:
                contour_set.interval = float(interval)
            return contour_set
        if not path.exists():
            raise SourceError(f"{path}: file not found")
        if suffix not in DEM_SUFFIXES:
            raise SourceError(
                f"{path}: unknown format {path.suffix or '(no extension)'!r}; expected one of "
                f"{', '.join(SUPPORTED_SUFFIXES)}"
            )
        dem, name = path, str(path)
    if interval is None:
        raise InvalidParameter(f"{name}: a DEM needs a contour interval", parameter="interval")
    return contours_from_dem(
        dem, interval=interval, tolerances=tolerances, block=block, executor=executor, scratch=scratch
    )
