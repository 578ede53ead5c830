"""Tests of reading contour files (GeoJSON, GeoPackage, Shapefile) and of write_geojson."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.testing import assert_allclose
from pyogrio.raw import write as ogr_write

from engine.errors import InvalidContour, SourceError
from engine.intervals import infer_interval
from engine.io.cleaning import dedup_mask
from engine.io.source import read_contours, read_source, write_geojson
from engine.io.vector_reader import ELEVATION_FIELDS
from engine.tolerances import Tolerances
from engine.types import BadFeature, ContourSet

DATA = Path(__file__).resolve().parents[2] / "data"

#: A point near Jacksboro, Tennessee, and its UTM 16N coordinates (metres).
LON0, LAT0 = -84.25, 36.6
TO_UTM = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32616", always_xy=True)
X0, Y0 = TO_UTM.transform(LON0, LAT0)


# ---------------------------------------------------------------------------------------------- helpers
def ring_utm(radius_m: float, n: int = 16, *, close: bool = True) -> list[tuple[float, float]]:
    """A circle around (X0, Y0) in UTM 16N, first vertex repeated at the end when ``close``."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pts = [(X0 + radius_m * math.cos(t), Y0 + radius_m * math.sin(t)) for t in a]
    return pts + [pts[0]] if close else pts


def write_vector(
    path: Path,
    geoms: list[shapely.Geometry | None],
    fields: dict[str, list[Any]],
    *,
    crs: str | None = "EPSG:32616",
    geometry_type: str = "Unknown",
    layer: str | None = None,
) -> Path:
    """Write features with pyogrio (driver from the extension)."""
    wkb = np.array([None if g is None else shapely.to_wkb(g) for g in geoms], dtype=object)
    names = list(fields)
    data = [
        np.asarray(v) if not any(x is None for x in v) else np.array(v, dtype=object) for v in fields.values()
    ]
    kwargs: dict[str, Any] = {"geometry_type": geometry_type, "layer": layer}
    if crs is not None:
        kwargs["crs"] = crs
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="'crs' was not provided", category=UserWarning)
        ogr_write(path, wkb, data, names, **kwargs)
    return path


def write_geojson_dict(path: Path, features: list[dict[str, Any]], crs_name: str | None = None) -> Path:
    fc: dict[str, Any] = {"type": "FeatureCollection", "features": features}
    if crs_name is not None:
        fc["crs"] = {"type": "name", "properties": {"name": crs_name}}
    path.write_text(json.dumps(fc))
    return path


def feature(geometry: dict[str, Any] | None, **props: Any) -> dict[str, Any]:
    return {"type": "Feature", "properties": props, "geometry": geometry}


def line(coords: list[tuple[float, float]]) -> dict[str, Any]:
    return {"type": "LineString", "coordinates": [list(c) for c in coords]}


def bad_by_id(cs: ContourSet) -> dict[Any, str]:
    return {b.id: b.reason for b in cs.bad_features}


# ------------------------------------------------------------------------------------- formats
def test_geojson_fixture(tmp_path: Path) -> None:
    cs = read_source(DATA / "small_contours.geojson")
    assert cs.name == "small_contours"
    assert cs.source_crs == "EPSG:4326"
    assert cs.working_crs == "EPSG:32616"
    assert [c.id for c in cs.contours] == ["r400", "r420", "open380", "multi:0", "multi:1"]
    assert [c.closed for c in cs.contours] == [True, True, False, False, False]
    r400 = cs.contours[0]
    assert r400.elevation == 400.0
    assert r400.n_vertices == 12  # 13 positions in the file, the repeated one dropped
    assert r400.coords.dtype == np.float64 and r400.coords.shape == (12, 2)
    # Metres of UTM 16N: the ring is 0.01° (about 1.1 km) in radius around (X0, Y0).
    radii = np.hypot(r400.coords[:, 0] - X0, r400.coords[:, 1] - Y0)
    assert_allclose(radii, 1111.0, rtol=0.01)
    assert cs.interval == 20.0  # inferred from the levels 360, 380, 400, 420
    assert all(b.where == "small_contours.geojson" for b in cs.bad_features)


def test_geojson_fixture_bad_features() -> None:
    reasons = bad_by_id(read_source(DATA / "small_contours.geojson"))
    assert reasons == {
        "no_elev": "no elevation in field 'ELEV'",
        "point": "Point is not a line",
        "polygon": "Polygon is not a line",
        "no_geometry": "no geometry",
        "one_point": "fewer than 2 distinct points",
        "lat_95": "coordinates out of range for EPSG:4326 (-84.26, 95)",
    }


@pytest.mark.parametrize("suffix", [".gpkg", ".shp", ".geojson"])
def test_each_vector_format(tmp_path: Path, suffix: str) -> None:
    geoms = [shapely.LineString(ring_utm(500.0)), shapely.LineString([(X0, Y0), (X0 + 100, Y0 + 50)])]
    path = write_vector(tmp_path / f"c{suffix}", geoms, {"ELEV": [400.0, 380.0]}, geometry_type="LineString")
    cs = read_source(path)
    assert cs.source_crs == "EPSG:32616"
    assert cs.working_crs == "EPSG:32616"  # already metric: kept
    assert [c.closed for c in cs.contours] == [True, False]
    assert [c.elevation for c in cs.contours] == [400.0, 380.0]
    assert_allclose(cs.contours[0].coords, np.array(ring_utm(500.0, close=False)), atol=1e-6)
    assert cs.bad_features == []


def test_gpkg_ids_are_fids_and_layer_is_chosen(tmp_path: Path) -> None:
    path = tmp_path / "two_layers.gpkg"
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    write_vector(path, [seg, seg], {"ele": [100, 120]}, layer="contours")
    write_vector(path, [seg], {"ele": [7]}, layer="other")
    first = read_source(path)  # the first layer by default
    assert [c.id for c in first.contours] == [1, 2]  # GeoPackage FIDs start at 1
    other = read_source(path, layer="other")
    assert [c.elevation for c in other.contours] == [7.0]
    with pytest.raises(SourceError, match="nope"):
        read_source(path, layer="nope")


def test_shapefile_ids_are_the_index(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "c.shp", [seg, seg, seg], {"ELEV": [1, 2, 3]}, geometry_type="LineString")
    assert [c.id for c in read_source(path).contours] == [0, 1, 2]


def test_id_field_wins_over_fid(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "c.gpkg", [seg, seg], {"ele": [1, 2], "ID": ["a", "b"]})
    assert [c.id for c in read_source(path).contours] == ["a", "b"]


def test_multilinestring_gives_one_contour_per_part(tmp_path: Path) -> None:
    multi = shapely.MultiLineString(
        [[(X0, Y0), (X0 + 100, Y0)], [(X0, Y0 + 200), (X0 + 100, Y0 + 200)], ring_utm(50.0)]
    )
    path = write_vector(tmp_path / "m.gpkg", [multi], {"ele": [300.0]})
    cs = read_source(path)
    assert [c.id for c in cs.contours] == ["1:0", "1:1", "1:2"]
    assert [c.closed for c in cs.contours] == [False, False, True]
    assert {c.elevation for c in cs.contours} == {300.0}


# ------------------------------------------------------------------------------- elevation field
@pytest.mark.parametrize("name", ["ele", "ELE", "Elev", "ELEVATION", "z", "Height", "CONTOUR"])
def test_elevation_field_found_by_name(tmp_path: Path, name: str) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson", [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), **{name: 250})]
    )
    assert read_source(path).contours[0].elevation == 250.0


def test_elevation_field_precedence(tmp_path: Path) -> None:
    # "height" comes first in the file, but "ele" comes first in the search order.
    path = write_geojson_dict(
        tmp_path / "c.geojson",
        [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), height=1, contour=2, ele=3)],
    )
    assert ELEVATION_FIELDS[0] == "ele"
    assert read_source(path).contours[0].elevation == 3.0


def test_explicit_elevation_field(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson", [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), ele=1, hoehe=812.5)]
    )
    assert read_source(path, elevation_field="hoehe").contours[0].elevation == 812.5
    assert read_source(path, elevation_field="HOEHE").contours[0].elevation == 812.5


def test_missing_explicit_field_names_it_and_lists_fields(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson", [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), ele=1, name="x")]
    )
    with pytest.raises(SourceError, match=r"elevation field 'alt' not found; available fields: ele, name"):
        read_source(path, elevation_field="alt")


def test_no_elevation_field_found(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson", [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), alt=1)]
    )
    with pytest.raises(SourceError, match=r"no elevation field found.*available fields: alt"):
        read_source(path)


def test_text_elevations_are_parsed_or_rejected(tmp_path: Path) -> None:
    geom = line([(LON0, LAT0), (LON0 + 0.01, LAT0)])
    path = write_geojson_dict(
        tmp_path / "c.geojson",
        [
            feature(geom, id="num", ele="520"),
            feature(geom, id="abc", ele="abc"),
            feature(geom, id="blank", ele=" "),
        ],
    )
    cs = read_source(path)
    assert [(c.id, c.elevation) for c in cs.contours] == [("num", 520.0)]
    assert bad_by_id(cs) == {
        "abc": "elevation 'abc' in field 'ele' is not a number",
        "blank": "no elevation in field 'ele'",
    }


def test_nan_and_null_elevations_in_a_numeric_field(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "c.gpkg", [seg, seg, seg], {"ele": [100.0, np.nan, np.inf]})
    cs = read_source(path)
    assert [c.id for c in cs.contours] == [1]
    assert bad_by_id(cs) == {
        2: "no elevation in field 'ele'",
        3: "elevation inf in field 'ele' is not finite",
    }


# -------------------------------------------------------------------------------- bad geometries
def test_each_bad_geometry_reason_with_its_id(tmp_path: Path) -> None:
    good = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    with np.errstate(invalid="ignore"):
        nan_line = shapely.LineString([(X0, Y0), (np.nan, Y0), (X0 + 100, Y0)])
    geoms = [
        good,
        shapely.Point(X0, Y0),
        shapely.Polygon(ring_utm(100.0)),
        shapely.MultiPoint([(X0, Y0), (X0 + 1, Y0)]),
        None,
        shapely.LineString(),
        shapely.LineString([(X0, Y0), (X0, Y0), (X0 + 0.0002, Y0)]),  # all within 1 mm
        shapely.LineString([(X0, Y0), (X0 + 100, Y0), (X0, Y0)]),  # ring of 2 distinct points
        shapely.LineString([(X0, Y0), (X0 + 0.005, Y0)]),  # 5 mm long
        nan_line,
        shapely.LineString([(X0, Y0), (1e9, Y0)]),  # no longer on Earth in UTM 16N
    ]
    ids = ["good", "point", "polygon", "multipoint", "none", "empty", "dot", "ring2", "short", "nan", "far"]
    path = write_vector(tmp_path / "bad.gpkg", geoms, {"ele": [100.0] * len(ids), "id": ids})
    cs = read_source(path)
    assert [c.id for c in cs.contours] == ["good"]
    reasons = bad_by_id(cs)
    assert reasons == {
        "point": "Point is not a line",
        "polygon": "Polygon is not a line",
        "multipoint": "MultiPoint is not a line",
        "none": "no geometry",
        "empty": "empty geometry",
        "dot": "fewer than 2 distinct points",
        "ring2": "closed ring with fewer than 3 distinct points",
        "short": "zero length (0.005 m)",
        "nan": "NaN or infinite coordinates",
        "far": f"coordinates out of range for EPSG:32616 (1e+09, {Y0:.8g})",
    }
    assert all(isinstance(b, BadFeature) and b.where == "bad.gpkg" for b in cs.bad_features)


def test_geographic_out_of_range_longitude(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson",
        [
            feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), id="ok", ele=1),
            feature(line([(LON0, LAT0), (190.0, LAT0)]), id="lon190", ele=1),
        ],
    )
    assert bad_by_id(read_source(path)) == {"lon190": "coordinates out of range for EPSG:4326 (190, 36.6)"}


def test_a_bad_feature_does_not_move_the_working_crs(tmp_path: Path) -> None:
    # A feature at lat 95 would otherwise drag the extent's centre north; it is set aside first.
    path = write_geojson_dict(
        tmp_path / "c.geojson",
        [
            feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), ele=1),
            feature(line([(10.0, 95.0), (10.0, 96.0)]), ele=1),
        ],
    )
    assert read_source(path).working_crs == "EPSG:32616"


def test_everything_bad_raises(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.geojson", [feature({"type": "Point", "coordinates": [0, 0]}, ele=1)]
    )
    with pytest.raises(SourceError, match=r"c.geojson: no usable contour.*Point is not a line"):
        read_source(path)


# ----------------------------------------------------------------------- rings and duplicates
def test_ring_closed_within_a_millimetre_and_duplicates_dropped(tmp_path: Path) -> None:
    pts = ring_utm(200.0, n=8, close=False)
    # A doubled vertex, a vertex 0.4 mm off the previous one, and a closing vertex 0.5 mm off the first.
    coords = [
        pts[0],
        pts[1],
        pts[1],
        (pts[2][0] + 0.0004, pts[2][1]),
        pts[2],
        *pts[3:],
        (pts[0][0] + 0.0005, pts[0][1]),
    ]
    path = write_vector(tmp_path / "r.gpkg", [shapely.LineString(coords)], {"ele": [100.0]})
    (contour,) = read_source(path).contours
    assert contour.closed
    assert contour.n_vertices == 8
    assert_allclose(contour.coords[:3], np.array(pts[:3]) + [[0, 0], [0, 0], [0.0004, 0]], atol=1e-9)


def test_open_line_is_not_closed(tmp_path: Path) -> None:
    coords = [(X0, Y0), (X0 + 100, Y0), (X0 + 100, Y0 + 100), (X0, Y0 + 0.002)]  # ends 2 mm apart
    path = write_vector(tmp_path / "o.gpkg", [shapely.LineString(coords)], {"ele": [100.0]})
    (contour,) = read_source(path).contours
    assert not contour.closed and contour.n_vertices == 4


def test_ring_with_repeated_closing_vertices(tmp_path: Path) -> None:
    a, b, c = (X0, Y0), (X0 + 100, Y0), (X0, Y0 + 100)
    path = write_vector(tmp_path / "r.gpkg", [shapely.LineString([a, b, c, a, a])], {"ele": [100.0]})
    (contour,) = read_source(path).contours
    assert contour.closed
    assert_allclose(contour.coords, [a, b, c])


def test_custom_tolerances(tmp_path: Path) -> None:
    coords = [(X0, Y0), (X0 + 0.5, Y0), (X0 + 100, Y0)]
    path = write_vector(tmp_path / "t.gpkg", [shapely.LineString(coords)], {"ele": [1.0]})
    assert read_source(path).contours[0].n_vertices == 3
    assert read_source(path, tolerances=Tolerances(duplicate_m=1.0)).contours[0].n_vertices == 2


def greedy_reference(xy: np.ndarray, dup: float) -> list[int]:
    """The sequential scan dedup_mask must reproduce: keep a vertex at least dup from the last kept one."""
    kept = [0]
    for i in range(1, len(xy)):
        if math.dist(xy[i], xy[kept[-1]]) >= dup:
            kept.append(i)
    return kept


coords_strategy = arrays(
    np.float64,
    st.tuples(st.integers(1, 40), st.just(2)),
    elements=st.floats(min_value=-0.003, max_value=0.003, allow_nan=False),
)


@settings(max_examples=200, deadline=None)
@given(
    parts=st.lists(coords_strategy, min_size=1, max_size=4),
    closed_flags=st.lists(st.booleans(), min_size=4, max_size=4),
)
def test_dedup_never_leaves_close_consecutive_points(
    parts: list[np.ndarray], closed_flags: list[bool]
) -> None:
    dup = 1e-3
    xy = np.vstack(parts)
    part_of = np.repeat(np.arange(len(parts)), [len(p) for p in parts])
    closed = np.array(closed_flags[: len(parts)])
    keep = dedup_mask(xy, part_of, np.ones(len(xy), dtype=bool), closed, dup)
    offset = 0
    for k, p in enumerate(parts):
        kept = np.flatnonzero(keep[offset : offset + len(p)])
        assert kept[0] == 0  # the first vertex always stays
        steps = np.hypot(*np.diff(p[kept], axis=0).T)
        assert (steps >= dup).all()
        expected = greedy_reference(p, dup)
        if closed[k]:
            while len(expected) > 1 and math.dist(p[expected[-1]], p[0]) < dup:
                expected.pop()
            assert len(kept) == 1 or math.dist(p[kept[-1]], p[0]) >= dup
        assert kept.tolist() == expected
        offset += len(p)


def test_infer_interval() -> None:
    assert infer_interval(np.array([10.0, 30.0, 20.0, 50.0, 40.0, 100.0])) == 10.0
    assert infer_interval(np.array([5.0, 5.0])) is None


def test_explicit_interval_is_recorded(tmp_path: Path) -> None:
    assert read_source(DATA / "small_contours.geojson", interval=10).interval == 10.0


# ------------------------------------------------------------------------------------- errors
def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="nothere.geojson: file not found"):
        read_source(tmp_path / "nothere.geojson")


def test_unreadable_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.geojson"
    path.write_text("{not json")
    with pytest.raises(SourceError, match="broken.geojson: the file could not be read as contour lines"):
        read_source(path)


def test_unknown_format(tmp_path: Path) -> None:
    path = tmp_path / "contours.txt"
    path.write_text("hello")
    with pytest.raises(SourceError, match=r"contours.txt: unknown format '.txt'"):
        read_source(path)
    with pytest.raises(SourceError, match="unknown contour format"):
        read_contours(path)


def test_shapefile_without_prj(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "noprj.shp", [seg], {"ELEV": [1]}, crs=None, geometry_type="LineString")
    assert not path.with_suffix(".prj").exists()
    with pytest.raises(SourceError, match=r"noprj.shp: the file has no CRS \(is the .prj file missing\?\)"):
        read_source(path)


def test_gpkg_without_crs(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "nocrs.gpkg", [seg], {"ele": [1]}, crs=None)
    with pytest.raises(SourceError, match="nocrs.gpkg: the file has no CRS"):
        read_source(path)


def test_unknown_crs_in_prj(tmp_path: Path) -> None:
    seg = shapely.LineString([(X0, Y0), (X0 + 100, Y0)])
    path = write_vector(tmp_path / "odd.shp", [seg], {"ELEV": [1]}, crs=None, geometry_type="LineString")
    path.with_suffix(".prj").write_text("GEOGCS[nonsense")
    with pytest.raises(SourceError, match="odd.shp"):
        read_source(path)


def test_geojson_without_crs_is_wgs84(tmp_path: Path) -> None:
    path = write_geojson_dict(
        tmp_path / "c.json", [feature(line([(LON0, LAT0), (LON0 + 0.01, LAT0)]), ele=1)]
    )
    cs = read_source(path)
    assert cs.source_crs == "EPSG:4326"
    assert_allclose(cs.contours[0].coords[0], [X0, Y0], atol=1e-6)


# --------------------------------------------------------------------------------- write_geojson
def contour_features(cs: ContourSet) -> list[tuple[np.ndarray, bool, dict[str, Any]]]:
    return [(c.coords, c.closed, {"id": c.id, "elevation": c.elevation}) for c in cs.contours]


def test_write_geojson_round_trip_within_a_centimetre(tmp_path: Path) -> None:
    source = read_source(DATA / "small_contours.geojson")
    out = tmp_path / "out.geojson"
    write_geojson(out, contour_features(source), from_crs=source.working_crs)
    back = read_source(out)
    assert [c.id for c in back.contours] == [c.id for c in source.contours]
    assert [c.closed for c in back.contours] == [c.closed for c in source.contours]
    for a, b in zip(source.contours, back.contours, strict=True):
        assert a.elevation == b.elevation
        assert a.coords.shape == b.coords.shape
        assert np.hypot(*(a.coords - b.coords).T).max() < 0.01


def test_write_geojson_rfc7946_layout(tmp_path: Path) -> None:
    ring = np.array(ring_utm(300.0, n=5, close=False))
    out = tmp_path / "out.geojson"
    write_geojson(
        out,
        [(ring, True, {"id": np.int64(3), "elevation": np.float64(400.0)}), (ring[:2], False, {"id": "x"})],
        from_crs="EPSG:32616",
        decimals=6,
    )
    doc = json.loads(out.read_text())
    assert "crs" not in doc  # RFC 7946: WGS 84 longitude/latitude, no crs member
    first, second = doc["features"]
    assert first["properties"] == {"id": 3, "elevation": 400.0}
    assert first["geometry"]["type"] == "LineString"
    coords = first["geometry"]["coordinates"]
    assert len(coords) == 6 and coords[0] == coords[-1]  # ring written closed
    assert len(second["geometry"]["coordinates"]) == 2
    lon, lat = coords[0]
    assert -85 < lon < -84 and 36 < lat < 37  # longitude first
    assert all(round(v, 6) == v for xy in coords for v in xy)


@pytest.mark.parametrize("to_crs", ["EPSG:3857", "EPSG:32616"])
def test_write_geojson_other_crs_is_named(tmp_path: Path, to_crs: str) -> None:
    source = read_source(DATA / "small_contours.geojson")
    out = tmp_path / "out.geojson"
    write_geojson(out, contour_features(source), from_crs=source.working_crs, to_crs=to_crs)
    doc = json.loads(out.read_text())
    assert doc["crs"]["properties"]["name"] == f"urn:ogc:def:crs:EPSG::{to_crs.split(':')[1]}"
    back = read_source(out)
    assert back.source_crs == to_crs
    assert back.working_crs == "EPSG:32616"  # UTM, also for Web Mercator input
    ref = source.contours[0].coords
    got = back.contours[0].coords
    assert np.hypot(*(ref - got).T).max() < 0.01


def test_write_geojson_custom_crs_as_wkt(tmp_path: Path) -> None:
    custom = pyproj.CRS.from_proj4("+proj=tmerc +lon_0=-84.2 +lat_0=36 +k=1 +ellps=GRS80 +units=m").to_wkt()
    out = tmp_path / "out.geojson"
    write_geojson(
        out, [(np.array([[0.0, 0.0], [100.0, 50.0]]), False, {"ele": 1})], from_crs=custom, to_crs=custom
    )
    back = read_source(out)
    assert pyproj.CRS(back.source_crs).equals(pyproj.CRS(custom))
    assert_allclose(back.contours[0].coords, [[0.0, 0.0], [100.0, 50.0]], atol=1e-3)


def test_write_geojson_rejects_bad_input(tmp_path: Path) -> None:
    with pytest.raises(InvalidContour, match="2 positions"):
        write_geojson(
            tmp_path / "o.geojson", [(np.array([[0.0, 0.0]]), False, {"id": 1})], from_crs="EPSG:32616"
        )
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        write_geojson(tmp_path / "o.geojson", [(np.zeros((3, 3)), False, {})], from_crs="EPSG:32616")
    with pytest.raises(InvalidContour, match="cannot be transformed"):
        write_geojson(
            tmp_path / "o.geojson",
            [(np.array([[1e20, 0.0], [0.0, 0.0]]), False, {"id": 1})],
            from_crs="EPSG:32616",
        )
    assert not (tmp_path / "o.geojson").exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind


def test_issue_12_a_source_assembled_in_small_batches_gives_the_contours_and_reasons_of_one_batch(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Parts are checked and projected in batches so a big source's temporaries stay small; the result must not
    depend on the batch size (the working CRS comes from every batch's extent, reasons keep their order)."""
    import engine.io.cleaning as cleaning
    from engine.io.source import sample_contours_path

    sample = json.loads(sample_contours_path().read_text())
    features = sample["features"][:300]
    features[3]["geometry"]["coordinates"] = [[float("nan"), 36.0], [-84.1, 36.1]]
    features[40]["geometry"]["coordinates"] = features[40]["geometry"]["coordinates"][:1] * 2
    features[200]["geometry"]["coordinates"][5] = [-84.1, 95.0]
    path = tmp_path / "mixed.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    whole = read_source(path)
    monkeypatch.setattr(cleaning, "ASSEMBLE_BATCH_VERTICES", 50)
    batched = read_source(path)
    assert len(whole.bad_features) >= 3
    assert [(b.id, b.reason) for b in batched.bad_features] == [(b.id, b.reason) for b in whole.bad_features]
    assert (batched.working_crs, batched.interval) == (whole.working_crs, whole.interval)
    assert len(batched.contours) == len(whole.contours) > 250
    for a, b in zip(batched.contours, whole.contours, strict=True):
        assert (a.id, a.elevation, a.closed) == (b.id, b.elevation, b.closed)
        np.testing.assert_array_equal(a.coords, b.coords)


def sample_lines(n: int) -> tuple[list[shapely.Geometry | None], list[float]]:
    """The lines (lon/lat) and elevations of the bundled sample's first ``n`` features."""
    from engine.io.source import sample_contours_path

    features = json.loads(sample_contours_path().read_text())["features"][:n]
    return [shapely.geometry.shape(f["geometry"]) for f in features], [f["properties"]["elevation"] for f in features]


@pytest.mark.parametrize("suffix", [".gpkg", ".shp", ".geojson"])
def test_issue_12_a_file_read_in_batches_gives_the_contour_set_of_one_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    """Every format is streamed a few features at a time; the contours, their ids (FIDs, parts) and the bad
    features with their reasons and order must be those of one read of every feature."""
    import engine.io.cleaning as cleaning
    import engine.io.vector_reader as vector

    geoms, elevations = sample_lines(240)
    geoms[150] = shapely.LineString([(-84.1, 36.5), (190.0, 36.5)])  # a Shapefile cannot hold NaN
    geoms[170] = None
    elevations[190] = float("nan")
    geoms[200] = shapely.MultiLineString([geoms[201], geoms[202]])
    geoms[220] = shapely.LineString([(-84.1, 36.5), (-84.1, 95.0)])
    path = write_vector(
        tmp_path / f"c{suffix}",
        geoms,
        {"elevation": elevations},
        crs="EPSG:4326",
        geometry_type="MultiLineString" if suffix == ".shp" else "Unknown",
    )
    reads: list[int] = []  # features in each read whose lines are made
    real_explode = vector._explode_lines

    def counted_explode(wkb: Any, *args: Any, **kwargs: Any) -> Any:
        reads.append(len(wkb))
        return real_explode(wkb, *args, **kwargs)

    monkeypatch.setattr(vector, "_explode_lines", counted_explode)
    monkeypatch.setattr(vector, "READ_VERTICES", 1 << 40)  # one read of every feature
    whole = read_source(path)
    assert reads == [240]
    reads.clear()
    monkeypatch.setattr(vector, "READ_VERTICES", None)
    monkeypatch.setattr(vector, "ARROW_BATCH_FEATURES", 16)
    monkeypatch.setattr(cleaning, "ASSEMBLE_BATCH_VERTICES", 1500)
    batched = read_source(path)

    assert len(reads) > 5 and sum(reads) == 240, reads  # the bad features are in later reads
    fid = 1 if suffix == ".gpkg" else 0  # the FID of the first feature
    assert [(b.id, b.reason) for b in whole.bad_features] == [
        (170 + fid, "no geometry"),
        (190 + fid, "no elevation in field 'elevation'"),
        (150 + fid, "coordinates out of range for EPSG:4326 (190, 36.5)"),
        (220 + fid, "coordinates out of range for EPSG:4326 (-84.1, 95)"),
    ]
    assert batched.bad_features == whole.bad_features
    assert f"{200 + fid}:1" in [c.id for c in whole.contours]
    assert (batched.working_crs, batched.source_crs, batched.interval) == (
        whole.working_crs,
        whole.source_crs,
        whole.interval,
    )
    assert len(batched.contours) == len(whole.contours) == 237
    for a, b in zip(batched.contours, whole.contours, strict=True):
        assert (a.id, a.elevation, a.closed) == (b.id, b.elevation, b.closed)
        np.testing.assert_array_equal(a.coords, b.coords)
