"""Contour lines written to GeoJSON: a FeatureCollection of LineStrings, in WGS 84 as RFC 7946 has it or in any
CRS named in a ``crs`` member, written whole to a temporary file and renamed."""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from engine.errors import InvalidContour
from engine.io.crs import WGS84, as_coords, make_transformer, parse_crs
from engine.types import Coords


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
