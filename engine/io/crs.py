"""Coordinate reference systems: parsing, the metric working CRS, transformers and validity checks.

Simplification happens in metres (docs/design.md section 4): the data's own CRS when it is projected in metres,
else the UTM zone of the extent's centre. Never degrees.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
import pyproj
from numpy.typing import ArrayLike, NDArray
from pyproj.aoi import AreaOfInterest
from pyproj.database import query_utm_crs_info
from pyproj.exceptions import CRSError

from engine.errors import SourceError
from engine.types import Coords

#: The CRS of GeoJSON without a ``crs`` member (RFC 7946) and of the bundled ``.npz`` DEM layout.
WGS84 = "EPSG:4326"

#: Web Mercator, the CRS of map tiles.
WEB_MERCATOR = "EPSG:3857"

#: A projected coordinate more than this many degrees outside its CRS's area of use is treated as garbage.
#: Data a little outside the area of use is normal (a UTM zone stretched over the neighbouring zone), a wrong
#: unit or swapped axes put it hundreds of kilometres off.
AREA_OF_USE_MARGIN_DEG = 10.0

#: A projected coordinate whose trip to longitude/latitude and back moves it by more than this (metres of the
#: CRS) lies outside where the projection is defined (Web Mercator wraps longitudes beyond ±20,037 km, a
#: transverse Mercator far from its meridian does not invert).
ROUND_TRIP_LIMIT_M = 1.0

#: A function mapping (n, 2) coordinates to (n, 2) coordinates, (x, y) order on both sides.
CoordTransform = Callable[[ArrayLike], Coords]


def parse_crs(crs: str | pyproj.CRS, *, where: str = "") -> pyproj.CRS:
    """Parse a CRS given as an authority string, a WKT, a PROJ string or a :class:`pyproj.CRS`.

    Parameters
    ----------
    crs
        ``"EPSG:4326"``, a WKT string, ...
    where
        The file the CRS comes from, named in the error message.

    Returns
    -------
    pyproj.CRS
        The horizontal part of the CRS (a compound CRS's first component: heights are attributes here).

    Raises
    ------
    SourceError
        The CRS is empty or cannot be understood.
    """
    if isinstance(crs, pyproj.CRS):
        parsed = crs
    else:
        if not crs or not str(crs).strip():
            raise SourceError(f"{where or 'source'}: no CRS given")
        try:
            parsed = pyproj.CRS.from_user_input(crs)
        except CRSError as exc:
            raise SourceError(f"{where or 'source'}: unknown CRS {str(crs)[:80]!r} ({exc})") from exc
    if parsed.is_compound and parsed.sub_crs_list:
        parsed = parsed.sub_crs_list[0]
    return parsed


def crs_to_string(crs: pyproj.CRS) -> str:
    """Name a CRS by its authority code when it has one, else by its WKT.

    >>> crs_to_string(pyproj.CRS("OGC:CRS84"))
    'EPSG:4326'
    """
    # CRS84 differs from EPSG:4326 only in axis order, which ccsm never relies on (always_xy everywhere),
    # and "EPSG:4326" is what every downstream consumer expects.
    if crs.equals(pyproj.CRS("OGC:CRS84"), ignore_axis_order=True):
        return WGS84
    authority = crs.to_authority(min_confidence=90)
    if authority is not None:
        return f"{authority[0]}:{authority[1]}"
    return str(crs.to_wkt())


def is_metric_projected(crs: pyproj.CRS) -> bool:
    """True when the CRS is projected and both its axes are in metres.

    >>> is_metric_projected(pyproj.CRS("EPSG:32616")), is_metric_projected(pyproj.CRS("EPSG:2263"))
    (True, False)
    """
    if not crs.is_projected:
        return False
    axes = crs.axis_info[:2]
    return len(axes) == 2 and all(math.isclose(a.unit_conversion_factor, 1.0) for a in axes)


def is_web_mercator(crs: pyproj.CRS) -> bool:
    """True for Web Mercator (EPSG:3857 and its aliases), the CRS of map tiles.

    >>> is_web_mercator(pyproj.CRS("EPSG:3857")), is_web_mercator(pyproj.CRS("EPSG:32616"))
    (True, False)
    """
    operation = crs.coordinate_operation
    return operation is not None and "pseudo mercator" in operation.method_name.lower().replace("-", " ")


def _utm_zone_number(lon: float) -> int:
    """The regular 6° UTM zone of a longitude (ignores the Norway/Svalbard exceptions)."""
    return int(math.floor((lon + 180.0) / 6.0)) % 60 + 1


def choose_working_crs(source_crs: str, bounds_lonlat: tuple[float, float, float, float]) -> str:
    """Choose the metric CRS to simplify in.

    Parameters
    ----------
    source_crs
        The data's CRS (authority string or WKT).
    bounds_lonlat
        (west, south, east, north) of the data in degrees of longitude/latitude.

    Returns
    -------
    str
        ``source_crs`` (as :func:`crs_to_string` names it) when it is projected in metres, except Web
        Mercator, whose "metres" are true metres only at the equator (25 % too long at 36.6°, where the sample
        lies), so tolerances in metres would mean different things at different latitudes; else the WGS 84 UTM
        zone of the extent's centre (``"EPSG:326xx"`` north, ``"EPSG:327xx"`` south), or UPS beyond the UTM
        latitudes (84° N, 80° S). Never a CRS in degrees or feet.

    Raises
    ------
    SourceError
        ``source_crs`` cannot be parsed or the bounds are not finite longitudes/latitudes.

    Examples
    --------
    >>> choose_working_crs("EPSG:4326", (-84.41, 36.45, -84.08, 36.73))
    'EPSG:32616'
    >>> choose_working_crs("EPSG:32617", (-84.41, 36.45, -84.08, 36.73))
    'EPSG:32617'
    """
    crs = parse_crs(source_crs)
    if is_metric_projected(crs) and not is_web_mercator(crs):
        return crs_to_string(crs)
    west, south, east, north = (float(v) for v in bounds_lonlat)
    if not all(math.isfinite(v) for v in (west, south, east, north)) or not (-90 <= south <= north <= 90):
        raise SourceError(f"cannot choose a working CRS for bounds {bounds_lonlat}: not longitudes/latitudes")
    lon = (west + east) / 2.0
    lat = (south + north) / 2.0
    if lat > 84.0:
        return "EPSG:32661"  # WGS 84 / UPS North (E,N)
    if lat < -80.0:
        return "EPSG:32761"  # WGS 84 / UPS South (E,N)
    return _utm_for_point(lon, lat)


@functools.lru_cache(maxsize=256)
def _utm_for_point(lon: float, lat: float) -> str:
    """The WGS 84 UTM zone of a point (cached: pyproj's database query takes about 0.1 s)."""
    # A point area of interest: the zone of the centre, as the issue asks. On a zone boundary pyproj returns
    # both neighbouring zones, so prefer the one the 6° rule gives (the eastern one), for a stable answer.
    infos = query_utm_crs_info(
        datum_name="WGS 84", area_of_interest=AreaOfInterest(lon, lat, lon, lat), contains=False
    )
    hemisphere = "326" if lat >= 0 else "327"
    candidates = [i for i in infos if i.auth_name == "EPSG" and i.code.startswith(hemisphere)]
    wanted = f"{hemisphere}{_utm_zone_number(lon):02d}"
    for info in candidates:
        if info.code == wanted:
            return f"EPSG:{info.code}"
    if candidates:
        return f"EPSG:{candidates[0].code}"
    return f"EPSG:{wanted}"


def make_transformer(from_crs: str, to_crs: str) -> CoordTransform:
    """Build a function that transforms (n, 2) coordinates between two CRSs, (x, y) / (lon, lat) order.

    Parameters
    ----------
    from_crs, to_crs
        Authority strings or WKT.

    Returns
    -------
    Callable
        ``f(coords) -> coords``: (n, 2) array-like in ``from_crs`` to a new (n, 2) float64 array in
        ``to_crs``.
        Points that cannot be transformed come out as ``inf`` (no exception), so one bad vertex does not
        stop a whole file; callers check ``np.isfinite``.

    Raises
    ------
    SourceError
        A CRS cannot be parsed.

    Examples
    --------
    >>> f = make_transformer("EPSG:4326", "EPSG:3857")
    >>> f([[0.0, 0.0]]).tolist()
    [[0.0, 0.0]]
    """
    src = parse_crs(from_crs)
    dst = parse_crs(to_crs)
    if src.equals(dst, ignore_axis_order=True):
        return _copy_coords
    transformer = pyproj.Transformer.from_crs(src, dst, always_xy=True)

    def transform(coords: ArrayLike) -> Coords:
        xy = as_coords(coords)
        if xy.shape[0] == 0:
            return xy.copy()
        x, y = transformer.transform(xy[:, 0], xy[:, 1], errcheck=False)
        return np.column_stack([np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)])

    return transform


def as_coords(coords: ArrayLike) -> Coords:
    """Coerce to a (n, 2) float64 array.

    Raises
    ------
    ValueError
        The input is not of shape (n, 2).
    """
    xy = np.asarray(coords, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"coordinates must have shape (n, 2), got {xy.shape}")
    return xy


def _copy_coords(coords: ArrayLike) -> Coords:
    return as_coords(coords).copy()


def lonlat_validity(crs: pyproj.CRS, xy: Coords) -> tuple[Coords, NDArray[np.bool_]]:
    """Longitude/latitude of coordinates and whether each lies where the CRS is defined.

    Parameters
    ----------
    crs
        The CRS of ``xy``.
    xy
        (n, 2) float64 coordinates in ``crs``, all finite.

    Returns
    -------
    lonlat : (n, 2) float64
        Degrees (NaN where not valid).
    valid : (n,) bool
        Geographic CRS: |lon| <= 180 and |lat| <= 90. Projected CRS: transforms to finite lon/lat and back
        within :data:`ROUND_TRIP_LIMIT_M`, and lies within :data:`AREA_OF_USE_MARGIN_DEG` of the CRS's area
        of use.
    """
    if crs.is_geographic:
        lonlat = xy.astype(np.float64, copy=True)
        if crs.axis_info and not math.isclose(crs.axis_info[0].unit_conversion_factor, math.pi / 180.0):
            # Geographic CRSs in grads or radians are rare; convert through PROJ rather than guess.
            lonlat = make_transformer(crs_to_string(crs), WGS84)(xy)
        valid = (
            np.isfinite(lonlat).all(axis=1) & (np.abs(lonlat[:, 0]) <= 180.0) & (np.abs(lonlat[:, 1]) <= 90.0)
        )
    else:
        geodetic = crs.geodetic_crs or pyproj.CRS(WGS84)
        forward = pyproj.Transformer.from_crs(crs, geodetic, always_xy=True)
        lon, lat = forward.transform(xy[:, 0], xy[:, 1], errcheck=False)
        lonlat = np.column_stack([np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)])
        valid = (
            np.isfinite(lonlat).all(axis=1) & (np.abs(lonlat[:, 0]) <= 180.0) & (np.abs(lonlat[:, 1]) <= 90.0)
        )
        back_x, back_y = forward.transform(lonlat[:, 0], lonlat[:, 1], direction="INVERSE", errcheck=False)
        moved = np.hypot(np.asarray(back_x) - xy[:, 0], np.asarray(back_y) - xy[:, 1])
        with np.errstate(invalid="ignore"):
            valid &= moved <= ROUND_TRIP_LIMIT_M
        area = crs.area_of_use
        if area is not None:
            m = AREA_OF_USE_MARGIN_DEG
            with np.errstate(invalid="ignore"):
                valid &= (lonlat[:, 1] >= area.south - m) & (lonlat[:, 1] <= area.north + m)
                if area.west <= area.east:  # an area crossing the antimeridian is not checked in longitude
                    valid &= (lonlat[:, 0] >= area.west - m) & (lonlat[:, 0] <= area.east + m)
    lonlat[~valid] = np.nan
    return lonlat, valid
