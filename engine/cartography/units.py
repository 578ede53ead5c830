"""The vertical unit of a source, when the source states it (docs/design.md section 9.4)."""

from __future__ import annotations

import os
from pathlib import Path

from engine.io.dem import DEM_SUFFIXES, dem_vertical_units
from engine.io.vector_reader import VECTOR_SUFFIXES
from engine.io.vertical_units import elevation_units


def source_units(path: str | os.PathLike[str], elevation_field: str | None = None) -> str | None:
    """ "m" or "ft" as a contour file's elevation attribute name or a DEM's metadata says; None when silent.

    Raises
    ------
    SourceError
        The source cannot be read.
    """
    suffix = Path(path).suffix.lower()
    if suffix in VECTOR_SUFFIXES:
        return elevation_units(path, elevation_field)
    if suffix in DEM_SUFFIXES:
        return dem_vertical_units(path)
    return None
