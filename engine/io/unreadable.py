"""The message for a source file its reader does not recognise, in ccsm's words rather than GDAL's.

GDAL's own text ("not recognized as being in a supported file format ... prefixing the file path with
'<DRIVER>:'") gives advice for GDAL's command line tools, which a ccsm user cannot follow.
"""

from __future__ import annotations

from pathlib import Path

#: What ccsm reads, as the messages name it.
READ_FORMATS = (
    "contour lines from GeoJSON (.geojson, .json), GeoPackage (.gpkg) or Shapefile (.shp), "
    "and DEMs from GeoTIFF (.tif, .tiff), ESRI ASCII grid (.asc) or NumPy (.npz)"
)

#: GDAL's phrase for a file none of its drivers recognises.
_NOT_RECOGNISED = "not recognized as being in a supported file format"


def unreadable_message(path: Path, what: str, exc: BaseException) -> str:
    """``path: the file could not be read as {what} ...``: which formats ccsm reads, and GDAL's reason only
    when it says more than that the format is unknown (without its driver advice)."""
    reason = str(exc)
    head = f"{path}: the file could not be read as {what}"
    if _NOT_RECOGNISED in reason:
        return f"{head}; ccsm reads {READ_FORMATS}, and the file is none of them (damaged, or another format?)"
    return f"{head} ({reason.split('; It might help')[0].strip()})"
