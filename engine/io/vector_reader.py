"""Contour lines from and to vector files (GeoJSON, GeoPackage, Shapefile), and the cleaning of all sources.

Reading is vectorised: GDAL streams a layer's features in Arrow batches (pyogrio's ``open_arrow``, taken in by
nanoarrow), their geometries as WKB; shapely flattens a batch into one (N, 2) array with a part index, and one
pyproj call projects a batch's vertices. Python loops run per feature, never per vertex. Every format is read in
one pass a batch at a time, so a big file is never held whole.
"""

from __future__ import annotations

import json
import math
import os
import uuid
import warnings
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field, replace
from itertools import chain
from pathlib import Path
from typing import Any, NoReturn

import nanoarrow as na
import numpy as np
import pyproj
import shapely
from nanoarrow.iterator import UnregisteredExtensionWarning
from numpy.typing import NDArray
from pyogrio import list_layers, read_info
from pyogrio.errors import DataLayerError, DataSourceError
from pyogrio.raw import open_arrow

from engine.errors import InvalidContour, SourceError
from engine.io.crs import (
    WGS84,
    as_coords,
    choose_working_crs,
    crs_to_string,
    lonlat_validity,
    make_transformer,
    parse_crs,
)
from engine.io.scratch import ReadScratch, ScratchContours
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import BadFeature, Contour, ContourSet, Coords, FeatureId

#: Names of the elevation attribute, tried in this order, case-insensitively.
ELEVATION_FIELDS: tuple[str, ...] = ("ele", "elev", "elevation", "z", "height", "contour")

#: File extensions read as contour lines.
VECTOR_SUFFIXES: tuple[str, ...] = (".geojson", ".json", ".gpkg", ".shp")

#: Features GDAL puts in one Arrow batch of a contour file's stream: few, since a long line has tens of thousands
#: of vertices. Batches are gathered into reads of about :data:`ASSEMBLE_BATCH_VERTICES` vertices.
ARROW_BATCH_FEATURES = 64
#: Bytes of WKB per vertex of a 2-D line, to tell from the blobs read how many vertices a read holds.
WKB_VERTEX_BYTES = 16
#: Vertices gathered into one read of a contour file before its lines are made (None: ASSEMBLE_BATCH_VERTICES).
READ_VERTICES: int | None = None

#: shapely geometry type ids (``shapely.get_type_id``) that are lines.
#: Largest latitude Web Mercator (EPSG:3857) covers: the edge of the square world; contours beyond cannot be
#: tiled, so they are reported as bad features at read time rather than accepted and then unservable.
WEB_MERCATOR_MAX_LAT = 85.0511287798066
#: Largest |elevation| accepted (metres or feet alike): far beyond any terrain, yet small enough that the
#: differences between elevations (the contour interval) stay finite.
MAX_ABS_ELEVATION = 1e6
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


@dataclass
class LineParts:
    """Candidate contour lines in the source CRS, before cleaning (one entry per line part).

    Attributes
    ----------
    xy
        (N, 2) float64 vertices of all parts, concatenated, in the source CRS.
    offsets
        (m + 1,) int64: part k is ``xy[offsets[k]:offsets[k + 1]]``.
    ids
        m feature ids.
    elevations
        (m,) float64 elevations (all finite: features without one are already in ``bad``).
    bad
        Features already rejected (bad geometry type, no elevation, ...).
    """

    xy: Coords
    offsets: NDArray[np.int64]
    ids: list[FeatureId]
    elevations: NDArray[np.float64]
    bad: list[BadFeature] = field(default_factory=list)


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
        Where the contours wait once read (see :func:`assemble_batches`); None = in memory.

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
        elev_name = field_names[_find_elevation_field(field_names, elevation_field, path)]
        id_name = next((name for name in field_names if name.lower() == "id"), None)
        reads = _feature_reads(stream, meta, path, layer, id_name, elev_name)
        first = next(reads, None)
        if first is None:
            raise SourceError(f"{path}: no features")
        batches = _line_parts(chain([first], reads), path, elev_name)
        del first  # the batches let go of each read once its lines are made
        return assemble_batches(
            batches, source_crs=source_crs, where=where, name=path.stem, tolerances=tolerances, scratch=scratch
        )


def _line_parts(reads: Iterable[_FeatureRead], path: Path, elev_name: str) -> Iterator[LineParts]:
    """The line parts of each read in turn, in batches of about :data:`ASSEMBLE_BATCH_VERTICES` vertices."""
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
    limit = (READ_VERTICES or ASSEMBLE_BATCH_VERTICES) * WKB_VERTEX_BYTES
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
        raise SourceError(f"{path}: cannot read contours ({exc})") from exc


def _find_elevation_field(field_names: Sequence[str], requested: str | None, path: Path) -> int:
    """Index of the elevation field among ``field_names`` (case-insensitive)."""
    lower = [name.lower() for name in field_names]
    if requested is not None:
        if requested in field_names:
            return field_names.index(requested)
        if requested.lower() in lower:
            return lower.index(requested.lower())
        raise SourceError(
            f"{path}: elevation field {requested!r} not found; available fields: {', '.join(field_names) or 'none'}"
        )
    for candidate in ELEVATION_FIELDS:
        if candidate in lower:
            return lower.index(candidate)
    raise SourceError(
        f"{path}: no elevation field found (looked for {', '.join(ELEVATION_FIELDS)}); "
        f"available fields: {', '.join(field_names) or 'none'}; pass elevation_field"
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


#: Vertices checked and projected at once while a source is assembled: the several temporary (n, 2) arrays of
#: a batch stay a few tens of MB whatever the size of the source (a national contour set has hundreds of
#: millions of vertices).
ASSEMBLE_BATCH_VERTICES = 1 << 20

#: Lists of a reader's scratch file (:class:`~engine.io.scratch.ReadScratch`): checked batches waiting for
#: the working CRS, and the usable contours.
CHECKED_LIST = "checked"
CONTOURS_LIST = "contours"


@dataclass
class _Checked:
    """A batch of parts checked in the source CRS: which parts are usable so far, why the others are not, and
    the lon/lat extent of the usable ones (None when there is none)."""

    ok: NDArray[np.bool_]
    reasons: dict[int, str]
    bounds: tuple[float, float, float, float] | None


def assemble_contours(
    parts: LineParts,
    *,
    source_crs: pyproj.CRS,
    where: str,
    name: str,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    interval: float | None = None,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """Validate, project and clean line parts into a :class:`ContourSet` (shared by vector and DEM sources).

    Per part, in this order: coordinates must be finite and valid for ``source_crs`` (see
    :func:`engine.io.crs.lonlat_validity`); all vertices are projected to the working CRS in one call; a part
    whose ends lie within ``tolerances.duplicate_m`` is a closed ring and loses its repeated last vertex;
    consecutive vertices closer than ``duplicate_m`` are merged (the first is kept); a line needs 2 distinct
    vertices, a ring 3, and a length of at least ``tolerances.zero_length_m``. Parts are handled in batches of
    about :data:`ASSEMBLE_BATCH_VERTICES` vertices (the working CRS is chosen first, from every batch's usable
    extent), so the temporary arrays are that size whatever the size of the source.

    Parameters
    ----------
    parts
        Line parts in ``source_crs``.
    source_crs
        Their CRS.
    where
        File name recorded in each :class:`BadFeature`.
    name
        Name of the set.
    tolerances
        Distances in metres of the working CRS.
    interval
        Contour interval; inferred from the elevations when None.
    scratch
        Where the contours wait once made (see :func:`assemble_batches`); None = in memory.

    Returns
    -------
    ContourSet

    Raises
    ------
    SourceError
        No part is usable.
    """
    return assemble_batches(
        in_batches(parts),
        source_crs=source_crs,
        where=where,
        name=name,
        tolerances=tolerances,
        interval=interval,
        scratch=scratch,
    )


def assemble_batches(
    batches: Iterable[LineParts],
    *,
    source_crs: pyproj.CRS,
    where: str,
    name: str,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    interval: float | None = None,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """:func:`assemble_contours` of line parts that come in batches (each of about
    :data:`ASSEMBLE_BATCH_VERTICES` vertices or fewer), so that a reader never holds the whole source.

    Two passes: each batch is checked in the source CRS as it comes, the working CRS is chosen from the
    extent of every usable part, then each batch is projected and cleaned. With ``scratch``, the checked
    batches wait in the scratch file between the passes and the contours are kept there too (the set's
    ``contours`` then read from it when asked, :class:`~engine.io.scratch.ScratchContours`); without, both
    stay in memory. Either way the same contours in the same order. Each batch's own ``bad`` (features
    rejected before it was made) is listed before the reasons found here.
    """
    bad: list[BadFeature] = []
    checked: list[tuple[LineParts, _Checked]] = []
    usable = []
    for batch in batches:
        check = _check_in_source_crs(batch, source_crs)
        bad.extend(batch.bad)
        batch = LineParts(batch.xy, batch.offsets, batch.ids, batch.elevations)  # its bad ones are listed
        if scratch is not None:
            scratch.extend(CHECKED_LIST, [(batch, check)])
        else:
            checked.append((batch, check))
        if check.bounds is not None:
            usable.append(check.bounds)
    # Read back one batch at a time: a batch is up to ASSEMBLE_BATCH_VERTICES vertices.
    waiting: Iterable[tuple[LineParts, _Checked]] = (
        scratch.read(CHECKED_LIST, batch=1) if scratch is not None else checked
    )
    if not usable:
        listed = [b for batch, c in waiting for b in _bad_from_reasons(batch, c.reasons, where)]
        _raise_nothing_usable(where, bad + listed)
    # The working CRS from the extent of the usable parts, then each batch projected with one call.
    extent = np.array(usable)
    bounds = (
        float(extent[:, 0].min()),
        float(extent[:, 1].min()),
        float(extent[:, 2].max()),
        float(extent[:, 3].max()),
    )
    source_text = crs_to_string(source_crs)
    working_crs = choose_working_crs(source_text, bounds)
    to_working = make_transformer(source_text, working_crs)
    contours: list[Contour] = []
    elevations: set[float] = set()  # for the interval, when it is to be inferred
    for batch, check in waiting:
        cleaned = _clean_in_working_crs(batch, check, to_working, working_crs, tolerances)
        elevations.update(c.elevation for c in cleaned)
        if scratch is not None:
            scratch.extend(CONTOURS_LIST, cleaned)
        else:
            contours.extend(cleaned)
        bad.extend(_bad_from_reasons(batch, check.reasons, where))
    if scratch is not None:
        scratch.drop(CHECKED_LIST)
    kept: Sequence[Contour] = ScratchContours(scratch, CONTOURS_LIST) if scratch is not None else contours
    if not kept:
        _raise_nothing_usable(where, bad)
    if interval is None:
        interval = infer_interval(np.array(sorted(elevations), dtype=np.float64))
    return ContourSet(
        contours=kept,
        working_crs=working_crs,
        source_crs=source_text,
        bad_features=bad,
        name=name,
        interval=interval,
    )


def in_batches(parts: LineParts) -> Iterator[LineParts]:
    """``parts`` in batches of about :data:`ASSEMBLE_BATCH_VERTICES` vertices; the first carries ``parts.bad``."""
    for k, (a, b) in enumerate(_batch_ranges(parts.offsets, ASSEMBLE_BATCH_VERTICES)):
        batch = _sub_parts(parts, a, b)
        yield replace(batch, bad=list(parts.bad)) if k == 0 else batch
    if len(parts.ids) == 0 and parts.bad:
        yield replace(parts, bad=list(parts.bad))


def _batch_ranges(offsets: NDArray[np.int64], vertices: int) -> list[tuple[int, int]]:
    """Consecutive part ranges [a, b) of about ``vertices`` vertices each (a bigger part makes a batch alone).

    >>> _batch_ranges(np.array([0, 3, 5, 20, 21]), 4)
    [(0, 1), (1, 2), (2, 3), (3, 4)]
    >>> _batch_ranges(np.array([0, 1, 2, 3]), 10)
    [(0, 3)]
    """
    n = len(offsets) - 1
    out: list[tuple[int, int]] = []
    a = 0
    while a < n:
        b = int(np.searchsorted(offsets, offsets[a] + vertices, side="right")) - 1
        b = min(max(b, a + 1), n)
        out.append((a, b))
        a = b
    return out


def _sub_parts(parts: LineParts, a: int, b: int) -> LineParts:
    """Parts a .. b - 1 as a LineParts of their own (the vertices a view, not a copy)."""
    lo, hi = int(parts.offsets[a]), int(parts.offsets[b])
    return LineParts(parts.xy[lo:hi], parts.offsets[a : b + 1] - lo, parts.ids[a:b], parts.elevations[a:b])


def _check_in_source_crs(parts: LineParts, source_crs: pyproj.CRS) -> _Checked:
    """Steps 1 and 2 of :func:`assemble_contours` for one batch: finite, valid for the CRS, within Web Mercator."""
    n_parts = len(parts.ids)
    counts = np.diff(parts.offsets)
    part_of = np.repeat(np.arange(n_parts), counts)
    xy = parts.xy
    ok = counts > 0
    reasons: dict[int, str] = {int(k): "empty geometry" for k in np.flatnonzero(~ok)}

    # 1. NaN / inf coordinates.
    finite_vertex: NDArray[np.bool_] = np.asarray(np.isfinite(xy).all(axis=1), dtype=np.bool_)
    for k in np.unique(part_of[~finite_vertex]):
        reasons.setdefault(int(k), "NaN or infinite coordinates")
    ok &= _all_per_part(finite_vertex, part_of, n_parts)

    # 2. Out of range for the source CRS (|lat| > 90, outside the projection's area of use...).
    candidate = ok[part_of]
    lonlat = np.full_like(xy, np.nan)
    valid_vertex = np.zeros(len(xy), dtype=bool)
    if candidate.any():
        lonlat[candidate], valid_vertex[candidate] = lonlat_validity(source_crs, xy[candidate])
    crs_label = _short_crs_name(source_crs)
    for k in np.unique(part_of[candidate & ~valid_vertex]).tolist():
        lo, hi = int(parts.offsets[k]), int(parts.offsets[k + 1])
        x, y = xy[lo + int(np.argmin(valid_vertex[lo:hi]))]  # the part's first invalid vertex
        reasons.setdefault(int(k), f"coordinates out of range for {crs_label} ({x:.8g}, {y:.8g})")
    ok &= _all_per_part(valid_vertex | ~candidate, part_of, n_parts)

    # 2b. Beyond Web Mercator's latitudes: valid coordinates, yet no tile can show them.
    ok &= ~_beyond_web_mercator(parts, part_of, ok, lonlat, reasons)
    if not ok.any():
        return _Checked(ok, reasons, None)
    ll = lonlat[ok[part_of]]
    return _Checked(
        ok, reasons, (float(ll[:, 0].min()), float(ll[:, 1].min()), float(ll[:, 0].max()), float(ll[:, 1].max()))
    )


def _clean_in_working_crs(
    parts: LineParts, check: _Checked, to_working: Any, working_crs: str, tolerances: Tolerances
) -> list[Contour]:
    """Steps 3 and 4 of :func:`assemble_contours` for one checked batch: projected, rings closed, duplicate
    vertices merged, too short parts left out (their reasons added to ``check.reasons``)."""
    n_parts = len(parts.ids)
    counts = np.diff(parts.offsets)
    part_of = np.repeat(np.arange(n_parts), counts)
    xy, ok, reasons = parts.xy, check.ok.copy(), check.reasons
    if not ok.any():
        return []
    use = ok[part_of]
    projected = np.full_like(xy, np.nan)
    projected[use] = to_working(xy[use])
    projected_ok = np.isfinite(projected).all(axis=1) | ~use
    for k in np.unique(part_of[~projected_ok]):
        reasons.setdefault(int(k), f"coordinates cannot be projected to {working_crs}")
    ok &= _all_per_part(projected_ok, part_of, n_parts)

    # 4. Rings, duplicate vertices, too few points, zero length.
    dup = float(tolerances.duplicate_m)
    starts = parts.offsets[:-1]
    ends = parts.offsets[1:] - 1
    closed = np.zeros(n_parts, dtype=bool)
    has_two = ok & (counts >= 2)
    gap = np.full(n_parts, np.inf)
    gap[has_two] = np.hypot(*(projected[ends[has_two]] - projected[starts[has_two]]).T)
    closed[has_two] = gap[has_two] < dup
    keep = ok[part_of].copy()
    keep[ends[closed]] = False  # a ring's repeated last vertex
    keep = dedup_mask(projected, part_of, keep, closed, dup)

    kept_counts = np.bincount(part_of[keep], minlength=n_parts)
    lengths = _part_lengths(projected, part_of, keep, closed, n_parts)
    for k in np.flatnonzero(ok):
        if kept_counts[k] < 2:
            reasons[int(k)] = "fewer than 2 distinct points"
        elif closed[k] and kept_counts[k] < 3:
            reasons[int(k)] = "closed ring with fewer than 3 distinct points"
        elif lengths[k] < tolerances.zero_length_m:
            reasons[int(k)] = f"zero length ({lengths[k]:.3g} m)"
    ok &= np.array([k not in reasons for k in range(n_parts)], dtype=bool)
    kept_xy = projected[keep]
    kept_offsets = np.concatenate([[0], np.cumsum(kept_counts)])
    return [
        Contour(
            id=parts.ids[k],
            elevation=float(parts.elevations[k]),
            coords=kept_xy[kept_offsets[k] : kept_offsets[k + 1]],
            closed=bool(closed[k]),
        )
        for k in np.flatnonzero(ok)
    ]


def _beyond_web_mercator(
    parts: LineParts,
    part_of: NDArray[np.int64],
    ok: NDArray[np.bool_],
    lonlat: NDArray[np.float64],
    reasons: dict[int, str],
) -> NDArray[np.bool_]:
    """(n_parts,) True for the usable parts with a vertex beyond ±WEB_MERCATOR_MAX_LAT (reason recorded)."""
    polar = ok[part_of] & (np.abs(lonlat[:, 1]) > WEB_MERCATOR_MAX_LAT)
    for k in np.unique(part_of[polar]).tolist():
        lo, hi = int(parts.offsets[k]), int(parts.offsets[k + 1])
        lat = float(lonlat[lo + int(np.argmax(np.abs(lonlat[lo:hi, 1])))][1])
        reasons.setdefault(int(k), f"latitude {lat:.6g} is outside Web Mercator's range (±{WEB_MERCATOR_MAX_LAT:.4f}°)")
    return np.isin(np.arange(len(ok)), part_of[polar])


def _bad_from_reasons(parts: LineParts, reasons: dict[int, str], where: str) -> list[BadFeature]:
    """BadFeatures for the parts in ``reasons`` (part index -> reason), in part order."""
    return [BadFeature(parts.ids[k], reason, where) for k, reason in sorted(reasons.items())]


def _raise_nothing_usable(where: str, listed: list[BadFeature]) -> NoReturn:
    sample = "; ".join(f"{b.id}: {b.reason}" for b in listed[:5])
    more = f" (and {len(listed) - 5} more)" if len(listed) > 5 else ""
    raise SourceError(f"{where}: no usable contour among {len(listed)} features: {sample}{more}")


def _short_crs_name(crs: pyproj.CRS) -> str:
    text = crs_to_string(crs)
    return text if len(text) < 40 else str(crs.name)


def _all_per_part(flag: NDArray[np.bool_], part_of: NDArray[np.int64], n_parts: int) -> NDArray[np.bool_]:
    """Per part: True when ``flag`` holds at every one of its vertices (and for parts without vertices)."""
    failures = np.bincount(part_of[~flag], minlength=n_parts)
    result: NDArray[np.bool_] = failures == 0
    return result


def dedup_mask(
    xy: Coords,
    part_of: NDArray[np.int64],
    keep: NDArray[np.bool_],
    closed: NDArray[np.bool_],
    dup: float,
) -> NDArray[np.bool_]:
    """Drop vertices closer than ``dup`` to the previous kept vertex of the same part.

    Greedy along each part, as a sequential scan would do: the first vertex of a part is always kept, a vertex
    is kept when it lies at least ``dup`` from the last kept one. For a closed part (stored without its
    repeated vertex) the last kept vertex must also lie at least ``dup`` from the first.

    Parameters
    ----------
    xy
        (N, 2) float64 coordinates in metres (rows with ``keep`` False are ignored and may be NaN).
    part_of
        (N,) int part index of each vertex, non-decreasing.
    keep
        (N,) bool, vertices still in play.
    closed
        (m,) bool per part.
    dup
        Distance in metres.

    Returns
    -------
    (N,) bool
        The new keep mask: consecutive kept vertices of a part are never closer than ``dup``.
    """
    keep = keep.copy()
    idx = np.flatnonzero(keep)
    if len(idx) >= 2:
        kept_parts = part_of[idx]
        same = kept_parts[1:] == kept_parts[:-1]
        step = np.hypot(*(xy[idx[1:]] - xy[idx[:-1]]).T)
        affected = np.unique(kept_parts[1:][same & (step < dup)])
        # The scan is sequential (whether a vertex stays depends on which earlier ones stayed), so it runs in
        # Python, but only over the parts that have a too-close pair at all: few in real data.
        bounds = np.searchsorted(kept_parts, np.stack([affected, affected + 1]))
        for lo, hi in bounds.T.tolist():
            members = idx[lo:hi]
            xs = xy[members, 0].tolist()
            ys = xy[members, 1].tolist()
            last_x, last_y = xs[0], ys[0]
            for j in range(1, len(members)):
                if math.hypot(xs[j] - last_x, ys[j] - last_y) < dup:
                    keep[members[j]] = False
                else:
                    last_x, last_y = xs[j], ys[j]
    # A ring must not end on top of its start.
    while True:
        idx = np.flatnonzero(keep)
        if len(idx) == 0:
            break
        kept_parts = part_of[idx]
        boundaries = np.flatnonzero(np.diff(kept_parts)) + 1
        first = idx[np.concatenate([[0], boundaries])]
        last = idx[np.concatenate([boundaries - 1, [len(idx) - 1]])]
        p = part_of[first]
        wrap = closed[p] & (last != first)
        wrap[wrap] = np.hypot(*(xy[last[wrap]] - xy[first[wrap]]).T) < dup
        if not wrap.any():
            break
        keep[last[wrap]] = False
    return keep


def _part_lengths(
    xy: Coords, part_of: NDArray[np.int64], keep: NDArray[np.bool_], closed: NDArray[np.bool_], n_parts: int
) -> NDArray[np.float64]:
    """Length in metres of each part's kept vertices (rings include their closing segment)."""
    idx = np.flatnonzero(keep)
    lengths = np.zeros(n_parts, dtype=np.float64)
    if len(idx) < 2:
        return lengths
    same = part_of[idx[1:]] == part_of[idx[:-1]]
    step = np.hypot(*(xy[idx[1:]] - xy[idx[:-1]]).T)
    np.add.at(lengths, part_of[idx[1:]][same], step[same])
    kept_parts = part_of[idx]
    boundaries = np.flatnonzero(np.diff(kept_parts)) + 1
    first = idx[np.concatenate([[0], boundaries])]
    last = idx[np.concatenate([boundaries - 1, [len(idx) - 1]])]
    p = part_of[first]
    ring = closed[p]
    lengths[p[ring]] += np.hypot(*(xy[last[ring]] - xy[first[ring]]).T)
    return lengths


def infer_interval(elevations: NDArray[np.float64]) -> float | None:
    """The contour interval: the most common step between consecutive distinct elevations.

    >>> infer_interval(np.array([100.0, 120.0, 140.0, 140.0, 200.0]))
    20.0
    """
    levels = np.unique(np.round(np.asarray(elevations, dtype=np.float64), 6))
    if len(levels) < 2:
        return None
    steps = np.round(np.diff(levels), 6)
    step = float(Counter(steps.tolist()).most_common(1)[0][0])
    return step if math.isfinite(step) else None


def write_geojson(
    path: str | os.PathLike[str],
    features: Iterable[tuple[Coords, bool, dict[str, Any]]],
    *,
    from_crs: str,
    to_crs: str = WGS84,
    decimals: int | None = None,
) -> None:
    """Write lines to a GeoJSON FeatureCollection of LineStrings.

    Parameters
    ----------
    path
        Output file; written to a temporary file first and renamed, so readers never see half a file.
    features
        ``(coords, closed, properties)``: (n, 2) coordinates in ``from_crs``, whether the line is a ring
        (stored without its repeated vertex: the first vertex is written again at the end), and JSON-able
        properties (numpy scalars are converted).
    from_crs
        CRS of the coordinates.
    to_crs
        Output CRS. EPSG:4326 follows RFC 7946 (longitude, latitude; no ``crs`` member); any other CRS
        (EPSG:3857, the source CRS, ...) is named in a ``crs`` member, as GDAL reads it.
    decimals
        Decimal places of the output coordinates. By default 7 in degrees (about 1 cm) and 3 in metres
        (1 mm), so a write/read round trip stays within 1 cm. RFC 7946 suggests 6 in degrees (about 10 cm).

    Raises
    ------
    InvalidContour
        A feature has fewer than 2 positions or coordinates that cannot be transformed.
    ValueError
        Coordinates are not of shape (n, 2).
    """
    target = parse_crs(to_crs)
    rfc7946 = target.equals(pyproj.CRS(WGS84), ignore_axis_order=True)
    if decimals is None:
        decimals = 7 if target.is_geographic else 3

    geometries: list[Coords] = []
    props: list[dict[str, Any]] = []
    for coords, closed, properties in features:
        xy = as_coords(coords)
        if closed and len(xy) > 0:
            xy = np.vstack([xy, xy[:1]])
        if len(xy) < 2:
            raise InvalidContour(
                f"feature {properties.get('id', len(props))!r}: a line needs 2 positions, got {len(xy)}"
            )
        geometries.append(xy)
        props.append(dict(properties))

    counts = np.array([len(g) for g in geometries], dtype=np.int64)
    all_xy = np.vstack(geometries) if geometries else np.empty((0, 2))
    out = make_transformer(from_crs, to_crs)(all_xy)
    finite = np.isfinite(out).all(axis=1)
    if not finite.all():
        k = int(np.searchsorted(np.cumsum(counts), int(np.flatnonzero(~finite)[0]), side="right"))
        raise InvalidContour(f"feature {props[k].get('id', k)!r}: coordinates cannot be transformed to {to_crs}")
    out = np.round(out, decimals)

    header: dict[str, Any] = {"type": "FeatureCollection"}
    if not rfc7946:
        authority = target.to_authority(min_confidence=90)
        crs_name = f"urn:ogc:def:crs:{authority[0]}::{authority[1]}" if authority else target.to_wkt()
        header["crs"] = {"type": "name", "properties": {"name": crs_name}}
    head = json.dumps(header)[:-1] + ', "features": [\n'

    lines = []
    start = 0
    for count, properties in zip(counts.tolist(), props, strict=True):
        feature = {
            "type": "Feature",
            "properties": properties,
            "geometry": {"type": "LineString", "coordinates": out[start : start + count].tolist()},
        }
        lines.append(json.dumps(feature, separators=(",", ":"), default=_json_default, allow_nan=False))
        start += count

    path = Path(path)
    # A uniquely named sibling, opened exclusively, then renamed over the target: readers never see half a
    # file, and the file gets the usual permissions (tempfile.mkstemp would make it private to the owner).
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "x", encoding="utf-8") as fh:
            fh.write(head)
            fh.write(",\n".join(lines))
            fh.write("\n]}\n")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _json_default(value: Any) -> Any:
    """Make numpy scalars and arrays JSON-able."""
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"property value {value!r} of type {type(value).__name__} is not JSON-serialisable")


#: Words in an elevation attribute's name that give its unit ("ELEV_FT", "contour_feet", "height_m").
UNIT_WORDS: dict[str, str] = {
    "ft": "ft",
    "feet": "ft",
    "foot": "ft",
    "m": "m",
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
}


def units_from_field_name(name: str) -> str | None:
    """The vertical unit an elevation attribute's name states ("ft" or "m"), or None.

    >>> units_from_field_name("ELEV_FT"), units_from_field_name("contour feet"), units_from_field_name("ele")
    ('ft', 'ft', None)
    """
    words = [w for w in "".join(c if c.isalnum() else " " for c in name.lower()).split() if w]
    found = {UNIT_WORDS[w] for w in words[1:] if w in UNIT_WORDS}  # the first word is the quantity
    return found.pop() if len(found) == 1 else None


def elevation_units(path: str | os.PathLike[str], elevation_field: str | None = None) -> str | None:
    """The vertical unit of a contour file as its elevation attribute's name states it, or None.

    Raises
    ------
    SourceError
        The file cannot be read, or has no such elevation field.
    """
    path = Path(path)
    try:
        meta = read_info(path, layer=str(list_layers(path)[0][0]))
    except (DataLayerError, DataSourceError, RuntimeError, IndexError) as exc:
        raise SourceError(f"{path}: cannot read contours ({exc})") from exc
    names = [str(n) for n in meta["fields"]]
    return units_from_field_name(names[_find_elevation_field(names, elevation_field, path)])
