"""Input and output of the engine: one entry point for every source format, and GeoJSON output.

``read_source`` dispatches on the file's extension: contour lines (GeoJSON, GeoPackage, Shapefile) are read
as they are, a DEM (GeoTIFF, ESRI ASCII grid, ``.npz``) is contoured at ``interval``. Either way the result
is a :class:`~engine.types.ContourSet` in metres of a projected working CRS.
"""

from __future__ import annotations

import os
from concurrent.futures import Executor
from pathlib import Path

from engine.errors import InvalidParameter, SourceError
from engine.io.crs import choose_working_crs, make_transformer
from engine.io.dem import DEM_SUFFIXES, contours_from_dem
from engine.io.geojson_writer import write_geojson
from engine.io.sample import sample_contours_path, sample_dem_path
from engine.io.vector_reader import VECTOR_SUFFIXES, read_contours
from engine.scratch import ReadScratch
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import ContourSet

__all__ = [
    "SUPPORTED_SUFFIXES",
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


def read_source(
    path: str | os.PathLike[str],
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
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in VECTOR_SUFFIXES:
        contour_set = read_contours(
            path, elevation_field=elevation_field, layer=layer, tolerances=tolerances, scratch=scratch
        )
        if interval is not None:
            contour_set.interval = float(interval)
        return contour_set
    if suffix in DEM_SUFFIXES:
        if not path.exists():
            raise SourceError(f"{path}: file not found")
        if interval is None:
            raise InvalidParameter(f"{path}: a DEM needs a contour interval", parameter="interval")
        return contours_from_dem(
            path, interval=interval, tolerances=tolerances, block=block, executor=executor, scratch=scratch
        )
    if not path.exists():
        raise SourceError(f"{path}: file not found")
    raise SourceError(
        f"{path}: unknown format {path.suffix or '(no extension)'!r}; expected one of {', '.join(SUPPORTED_SUFFIXES)}"
    )
