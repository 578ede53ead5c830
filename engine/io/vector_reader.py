"""Contour lines from vector files (GeoJSON, GeoPackage, Shapefile), read as a stream and handed to the cleaning.

Reading is vectorised: GDAL streams a layer's features in Arrow batches (pyogrio's ``open_arrow``, taken in by
nanoarrow), their geometries as WKB; shapely flattens a read into one (N, 2) array with a part index
(:class:`~engine.io.cleaning.LineParts`), which :mod:`engine.io.cleaning` checks, projects and cleans a batch at
a time. Python loops run per feature, never per vertex. Every format is read in one pass a batch at a time, so a
big file is never held whole.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import nanoarrow as na
import numpy as np
import shapely
from nanoarrow.iterator import UnregisteredExtensionWarning
from numpy.typing import NDArray
from pyogrio import list_layers, read_info
from pyogrio.errors import DataLayerError, DataSourceError
from pyogrio.raw import open_arrow

from engine.errors import SourceError
from engine.io import cleaning
from engine.io.cleaning import LineParts, assemble_batches, in_batches
from engine.io.crs import WGS84, parse_crs
from engine.io.unreadable import unreadable_message
from engine.scratch import ReadScratch
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import BadFeature, ContourSet, FeatureId

#: Names of the elevation attribute, tried in this order, case-insensitively.
ELEVATION_FIELDS: tuple[str, ...] = ("ele", "elev", "elevation", "z", "height", "contour")

#: File extensions read as contour lines.
VECTOR_SUFFIXES: tuple[str, ...] = (".geojson", ".json", ".gpkg", ".shp")

#: Features GDAL puts in one Arrow batch of a contour file's stream: few, since a long line has tens of thousands
#: of vertices. Batches are gathered into reads of about :data:`~engine.io.cleaning.ASSEMBLE_BATCH_VERTICES`
#: vertices.
ARROW_BATCH_FEATURES = 64
#: Bytes of WKB per vertex of a 2-D line, to tell from the blobs read how many vertices a read holds.
WKB_VERTEX_BYTES = 16
#: Vertices gathered into one read of a contour file before its lines are made (None: as many as the cleaning
#: takes in one batch, :data:`~engine.io.cleaning.ASSEMBLE_BATCH_VERTICES`).
READ_VERTICES: int | None = None

#: Largest |elevation| accepted (metres or feet alike): far beyond any terrain, yet small enough that the
#: differences between elevations (the contour interval) stay finite.
MAX_ABS_ELEVATION = 1e6
#: shapely geometry type ids (``shapely.get_type_id``) that are lines.
_LINE_TYPES = (1, 2)  # LineString, LinearRing
_MULTI_LINE = 5  # MultiLineString
_TYPE_NAMES = {
    0: "Point",
    1: "LineString",
    2: "LinearRing",
    3: "Polygon",
    4: "MultiPoint",
    5: "MultiLineString",
    6: "MultiPolygon",
    7: "GeometryCollection",
}


def read_contours(
    path: str | os.PathLike[str],
    *,
    elevation_field: str | None = None,
    layer: str | None = None,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """Read contour lines from a GeoJSON, GeoPackage or Shapefile.

    Parameters
    ----------
    path
        The file (``.geojson``, ``.json``, ``.gpkg``, ``.shp``).
    elevation_field
        Name of the elevation attribute. By default the first field named (case-insensitively) ``ele``,
        ``elev``, ``elevation``, ``z``, ``height`` or ``contour``, tried in that order.
    layer
        Layer name of a multi-layer file (GeoPackage); the first layer by default.
    tolerances
        ``duplicate_m`` merges consecutive vertices and closes rings, ``zero_length_m`` rejects dots.
    scratch
        Where the contours wait once read (see :func:`~engine.io.cleaning.assemble_batches`); None = in memory.

    Returns
    -------
    ContourSet
        Contours in metres of the working CRS (:func:`engine.io.crs.choose_working_crs`); one contour per
        LineString and per MultiLineString part (id ``"{fid}:{part}"``); closed rings without their repeated
        last vertex. Unusable features are listed in ``bad_features`` with a reason.

    Raises
    ------
    SourceError
        The file is missing or unreadable, the layer or the elevation field does not exist, the CRS is
        missing or unknown (GeoJSON without one is EPSG:4326), or no feature is usable.
    """
    path = Path(path)
    where = path.name
    if not path.exists():
        raise SourceError(f"{path}: file not found")
    if path.suffix.lower() not in VECTOR_SUFFIXES:
        raise SourceError(f"{path}: unknown contour format {path.suffix!r}; expected one of {VECTOR_SUFFIXES}")
    if layer is None:
        # Name the first layer explicitly: pyogrio warns when it has to pick one of several itself.
        with _as_source_error(path, layer):
            layer = str(list_layers(path)[0][0])
    with _feature_stream(path, layer) as (meta, stream):
        crs_text = meta.get("crs")
        if not crs_text:
            if path.suffix.lower() in (".geojson", ".json"):
                crs_text = WGS84  # RFC 7946: GeoJSON without a crs member is longitude/latitude on WGS 84
            else:
                hint = " (is the .prj file missing?)" if path.suffix.lower() == ".shp" else ""
                raise SourceError(f"{path}: the file has no CRS{hint}")
        source_crs = parse_crs(crs_text, where=str(path))

        field_names = [str(name) for name in meta["fields"]]
        try:
            elev_name = field_names[find_elevation_field(field_names, elevation_field, path)]
        except SourceError:
            if _feature_count(path, layer) == 0:  # an empty file has no fields either: say so, not which ones
                raise SourceError(f"{path}: the file has no features") from None
            raise
        id_name = next((name for name in field_names if name.lower() == "id"), None)
        reads = _feature_reads(stream, meta, path, layer, id_name, elev_name)
        first = next(reads, None)
        if first is None:
            raise SourceError(f"{path}: the file has no features")
        batches = _line_parts(chain([first], reads), path, elev_name)
        del first  # the batches let go of each read once its lines are made
        return assemble_batches(
            batches, source_crs=source_crs, where=where, name=path.stem, tolerances=tolerances, scratch=scratch
        )


def _line_parts(reads: Iterable[_FeatureRead], path: Path, elev_name: str) -> Iterator[LineParts]:
    """The line parts of each read in turn, in batches of about :data:`~engine.io.cleaning.ASSEMBLE_BATCH_VERTICES`
    vertices."""
    for read in reads:
        feature_ids = _feature_ids(read.fids, read.id_values, len(read.wkb), start=read.start)
        elevations, elev_reasons = _parse_elevations(read.elevations, elev_name)
        parts = _explode_lines(read.wkb, feature_ids, elevations, elev_reasons, path.name)
        del read  # the next read replaces this one rather than joining it in memory
        yield from in_batches(parts)


@dataclass
class _FeatureRead:
    """Features ``start`` .. ``start + len(wkb) - 1`` of a layer: their FIDs, WKB geometries (None: no
    geometry), ``id`` field values (None: no such field) and elevation field values."""

    fids: NDArray[Any] | None
    wkb: NDArray[Any]
    id_values: NDArray[Any] | None
    elevations: NDArray[Any]
    start: int


@contextmanager
def _feature_stream(path: Path, layer: str) -> Iterator[tuple[dict[str, Any], Any]]:
    """The layer's metadata (CRS, field names, FID column) and its features as a stream of Arrow batches of
    :data:`ARROW_BATCH_FEATURES` features (GDAL keeps its reading position from batch to batch, so each
    format is read in one pass)."""
    with ExitStack() as stack:
        with _as_source_error(path, layer):  # GeoJSON: GDAL reads the whole file once here, for its fields
            meta, reader = stack.enter_context(
                open_arrow(path, layer=layer, return_fids=True, batch_size=ARROW_BATCH_FEATURES, use_pyarrow=False)
            )
            stream = na.c_array_stream(reader)
        yield meta, stream


def _feature_reads(
    stream: Any, meta: dict[str, Any], path: Path, layer: str, id_name: str | None, elev_name: str
) -> Iterator[_FeatureRead]:
    """The stream's features gathered into reads of about :data:`READ_VERTICES` vertices (judged by the size
    of their WKB), each with the columns the contours need."""
    schema = stream.get_schema()
    names = [schema.child(i).name for i in range(schema.n_children)]
    columns = {
        "fids": names.index(meta["fid_column"]) if meta.get("fid_column") in names else None,
        "wkb": len(names) - 1,  # pyogrio puts the geometry last
        "id_values": None if id_name is None else names.index(id_name),
        "elevations": names.index(elev_name),
    }
    # Read through the module at call time: the cleaning's batch size is one setting, tuned in one place.
    limit = (READ_VERTICES or cleaning.ASSEMBLE_BATCH_VERTICES) * WKB_VERTEX_BYTES
    gathered: dict[str, list[Any]] = {key: [] for key in columns}
    start = size = 0
    batches = iter(stream)
    while True:
        with _as_source_error(path, layer):
            batch = next(batches, None)
        if batch is not None:
            values = na.Array(batch)
            with warnings.catch_warnings():  # the geometry's type is geoarrow.wkb: its binary storage is the WKB
                warnings.simplefilter("ignore", UnregisteredExtensionWarning)
                for key, col in columns.items():
                    if col is not None:
                        column = values.child(col).to_pylist()
                        gathered[key].extend(column)
                        if key == "wkb":
                            size += sum(len(blob) for blob in column if blob is not None)
        n = len(gathered["wkb"])
        if n and (batch is None or size >= limit or n * WKB_VERTEX_BYTES >= limit):
            yield _FeatureRead(
                fids=None if columns["fids"] is None else _as_array(gathered["fids"]),
                wkb=_as_array(gathered["wkb"]),
                id_values=None if id_name is None else _as_array(gathered["id_values"]),
                elevations=_as_array(gathered["elevations"]),
                start=start,
            )
            start += n
            gathered = {key: [] for key in columns}
            size = 0
        if batch is None:
            return


def _as_array(values: list[Any]) -> NDArray[Any]:
    """Field values as pyogrio's plain reads give them: numbers as a float or integer array (a missing number as
    NaN), anything else (text, bytes, a mixture) as an object array with None where missing."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        if len(present) == len(values) and all(isinstance(v, int) for v in present):
            return np.asarray(values, dtype=np.int64)
        return np.asarray([math.nan if v is None else v for v in values], dtype=np.float64)
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


@contextmanager
def _as_source_error(path: Path, layer: str | None) -> Iterator[None]:
    """GDAL's errors on opening or reading ``path`` as :class:`SourceError`."""
    try:
        yield
    except DataLayerError as exc:
        raise SourceError(f"{path}: cannot open layer {layer!r} ({exc})") from exc
    except (DataSourceError, RuntimeError, IndexError) as exc:  # nanoarrow's errors are RuntimeErrors
        raise SourceError(unreadable_message(path, "contour lines", exc)) from exc


def _feature_count(path: Path, layer: str) -> int | None:
    """How many features the layer holds, None when GDAL cannot tell without reading them all."""
    with _as_source_error(path, layer):
        count = int(read_info(path, layer=layer)["features"])
    return None if count < 0 else count


def find_elevation_field(field_names: Sequence[str], requested: str | None, path: Path) -> int:
    """Index of the elevation field among ``field_names`` (case-insensitive)."""
    lower = [name.lower() for name in field_names]
    if requested is not None:
        if requested in field_names:
            return field_names.index(requested)
        if requested.lower() in lower:
            return lower.index(requested.lower())
        raise SourceError(
            f"{path}: elevation field {requested!r} not found; available fields: {', '.join(field_names) or 'none'}",
            parameter="elevation_field",
        )
    for candidate in ELEVATION_FIELDS:
        if candidate in lower:
            return lower.index(candidate)
    raise SourceError(
        f"{path}: no elevation field found (looked for {', '.join(ELEVATION_FIELDS)}); "
        f"available fields: {', '.join(field_names) or 'none'}",
        parameter="elevation_field",
    )


def _to_feature_id(value: Any) -> FeatureId | None:
    """A JSON-friendly id from a field value (None when the value is missing)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            return None
        return int(value) if float(value).is_integer() else str(value)
    text = str(value)
    return text if text else None


def _feature_ids(
    fids: NDArray[Any] | None, id_values: NDArray[Any] | None, n: int, *, start: int = 0
) -> list[FeatureId]:
    """Per feature: its ``id`` field when set, else the file's FID, else its index in the file (the first of
    these ``n`` features is feature ``start``)."""
    ids: list[FeatureId] = []
    for i in range(n):
        fid: FeatureId | None = None
        if id_values is not None:
            fid = _to_feature_id(id_values[i])
        if fid is None and fids is not None:
            fid = _to_feature_id(fids[i])
        ids.append(start + i if fid is None else fid)
    return ids


def _parse_elevations(values: NDArray[Any], name: str) -> tuple[NDArray[np.float64], list[str | None]]:
    """Elevations as float64 (NaN when unusable) and, per feature, why it is unusable (None when fine)."""
    n = len(values)
    reasons: list[str | None] = [None] * n
    if values.dtype.kind in "iuf":
        elevations = values.astype(np.float64)
        for j in np.flatnonzero(~np.isfinite(elevations)).tolist():
            v = elevations[j]
            reasons[j] = (
                f"no elevation in field {name!r}" if np.isnan(v) else f"elevation {v} in field {name!r} is not finite"
            )
        magnitude = np.abs(np.nan_to_num(elevations, nan=0.0, posinf=0.0, neginf=0.0))
        for j in np.flatnonzero(magnitude > MAX_ABS_ELEVATION).tolist():
            reasons[j] = _elevation_too_large(elevations[j], name)
            elevations[j] = np.nan
        return elevations, reasons
    # Text (or mixed) fields: GDAL makes a field a string as soon as one feature holds text.
    elevations = np.full(n, np.nan, dtype=np.float64)
    for i, value in enumerate(values):
        if value is None or (isinstance(value, str) and not value.strip()):
            reasons[i] = f"no elevation in field {name!r}"
            continue
        try:
            number = float(value)
        except (TypeError, ValueError):
            reasons[i] = f"elevation {value!r} in field {name!r} is not a number"
            continue
        if math.isnan(number):
            reasons[i] = f"no elevation in field {name!r}"
        elif not math.isfinite(number):
            reasons[i] = f"elevation {value!r} in field {name!r} is not finite"
        elif abs(number) > MAX_ABS_ELEVATION:
            reasons[i] = _elevation_too_large(number, name)
        else:
            elevations[i] = number
    return elevations, reasons


def _elevation_too_large(value: float, name: str) -> str:
    return f"elevation {value:g} in field {name!r} is beyond ±{MAX_ABS_ELEVATION:g}"


def _geometries(wkb: NDArray[Any]) -> NDArray[Any]:
    """Shapely geometries of WKB blobs; one GEOS refuses (a LineString of one point) becomes None."""
    with np.errstate(invalid="ignore"):  # NaN coordinates are reported per feature below, not warned about
        try:
            return np.asarray(shapely.from_wkb(wkb), dtype=object)
        except shapely.errors.GEOSException:
            return np.asarray(shapely.from_wkb(wkb, on_invalid="ignore"), dtype=object)


def _explode_lines(
    wkb: NDArray[Any],
    feature_ids: list[FeatureId],
    elevations: NDArray[np.float64],
    elev_reasons: list[str | None],
    where: str,
) -> LineParts:
    """Split features into line parts (one per LineString or MultiLineString part), rejecting the rest."""
    geoms = _geometries(wkb)
    type_ids = shapely.get_type_id(geoms)  # -1 for a missing geometry
    bad: list[BadFeature] = []
    keep_geoms = []
    part_ids: list[FeatureId] = []
    part_elev: list[float] = []
    for i, (geom, type_id) in enumerate(zip(geoms, type_ids, strict=True)):
        fid = feature_ids[i]
        reason: str | None = None
        if geom is None and wkb[i] is not None:
            reason = "invalid geometry (a LineString needs at least 2 points)"
        elif geom is None or type_id < 0:
            reason = "no geometry"
        elif type_id not in _LINE_TYPES and type_id != _MULTI_LINE:
            reason = f"{_TYPE_NAMES.get(int(type_id), 'geometry')} is not a line"
        elif shapely.is_empty(geom):
            reason = "empty geometry"
        else:
            reason = elev_reasons[i]
        if reason is not None:
            bad.append(BadFeature(fid, reason, where))
            continue
        if type_id == _MULTI_LINE:
            for k, part in enumerate(shapely.get_parts(geom)):
                keep_geoms.append(part)
                part_ids.append(f"{fid}:{k}")
                part_elev.append(float(elevations[i]))
        else:
            keep_geoms.append(geom)
            part_ids.append(fid)
            part_elev.append(float(elevations[i]))
    if keep_geoms:
        xy, index = shapely.get_coordinates(np.asarray(keep_geoms, dtype=object), return_index=True)
        counts = np.bincount(index, minlength=len(keep_geoms))
    else:
        xy = np.empty((0, 2), dtype=np.float64)
        counts = np.zeros(0, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return LineParts(
        xy=np.ascontiguousarray(xy, dtype=np.float64),
        offsets=offsets,
        ids=part_ids,
        elevations=np.asarray(part_elev, dtype=np.float64),
        bad=bad,
    )
