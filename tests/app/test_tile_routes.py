import gzip
import math

import numpy as np
import pyproj
import pytest
import shapely
from support.mvt import decode

from engine.baselines import simplify_at_scale
from engine.build.datasets import SourceSpec, build_dataset
from engine.store.store import CCSStore
from engine.tiles.scale import zoom_for_scale
from tests.app.conftest import LAT0, LON0, synthetic_features, write_geojson
from tests.app.helpers import BUFFER, EXTENT, check_tile, grid_to_lonlat, lines_of, tile_for

MVT = "application/vnd.mapbox-vector-tile"


def url(z, x, y, query=""):
    return f"/tiles/hills/{z}/{x}/{y}.mvt" + (f"?{query}" if query else "")


def test_tile_headers_and_contract(client):
    r = client.get(url(*tile_for(LON0, LAT0, 13)))
    assert r.status_code == 200
    assert r.headers["content-type"] == MVT
    assert r.headers["cache-control"].startswith("public, max-age=")
    assert r.headers["etag"].startswith('"')
    features = check_tile(r.content)
    assert len(features) > 5
    assert any(f["properties"]["index"] for f in features)  # 400 m is a multiple of 5 x 20 m
    for f in features:
        e = f["properties"]["elevation"]
        assert f["properties"]["index"] == (e % 100 == 0)


def test_gzip_when_accepted(client):
    path = url(*tile_for(LON0, LAT0, 13))
    plain = client.get(path, headers={"accept-encoding": "identity"})
    zipped = client.get(path, headers={"accept-encoding": "gzip"})
    assert "content-encoding" not in plain.headers
    assert zipped.headers["content-encoding"] == "gzip"
    assert zipped.headers["vary"].startswith("Accept-Encoding")
    assert zipped.content == plain.content  # httpx decodes
    assert plain.headers["etag"] != zipped.headers["etag"]


def test_etag_304(client):
    path = url(*tile_for(LON0, LAT0, 12))
    r = client.get(path)
    again = client.get(path, headers={"if-none-match": r.headers["etag"]})
    assert again.status_code == 304 and again.content == b""
    assert again.headers["etag"] == r.headers["etag"]
    other = client.get(path + "?zoom=12.5", headers={"if-none-match": r.headers["etag"]})
    assert other.status_code == 200


def test_etag_names_t_only_for_a_method_that_honours_it(client):
    """A pinned t changes a ccsm tile, so its ETag; a baseline ignores t, so one cached tile serves every t."""
    path = url(*tile_for(LON0, LAT0, 12))
    ccsm = [client.get(path + f"?method=ccsm&t={t}").headers["etag"] for t in (0.2, 0.8)]
    dp = [client.get(path + f"?method=dp&t={t}").headers["etag"] for t in (0.2, 0.8)]
    assert ccsm[0] != ccsm[1]
    assert dp[0] == dp[1]


def test_etag_changes_with_the_data_version(client, tmp_path):
    path = url(*tile_for(LON0, LAT0, 12))
    old = client.get(path)
    version = client.get("/tiles/hills/tilejson.json").json()["data_version"]
    # Rebuild 'hills' from changed contours, through another handle on the store (as `ccsm build` would).
    changed = write_geojson(tmp_path / "hills.geojson", synthetic_features(seed=8))
    store = CCSStore(client.app.state.service.store.path)
    info, rebuilt = build_dataset(store, SourceSpec(changed, "hills", "hills"), workers=1)
    assert rebuilt and info.data_version > version
    tj = client.get("/tiles/hills/tilejson.json").json()
    assert tj["data_version"] == info.data_version and f"v={info.data_version}" in tj["tiles"][0]
    new = client.get(path, headers={"if-none-match": old.headers["etag"]})
    assert new.status_code == 200, "a stale ETag must not get a 304"
    assert new.headers["etag"] != old.headers["etag"]
    assert new.content != old.content and check_tile(new.content)
    assert client.get(path, headers={"if-none-match": new.headers["etag"]}).status_code == 304


def test_cors_on_get(client):
    """Any origin may read tiles (CCSM_CORS_ORIGINS defaults to '*'): the GET carries the CORS headers a page
    needs (the origin allowed, ETag and X-Tile-Scale readable), and the preflight allows GET and HEAD."""
    r = client.get(url(*tile_for(LON0, LAT0, 12)), headers={"origin": "https://example.org"})
    assert r.status_code == 200
    assert r.headers["access-control-allow-origin"] == "*"
    exposed = {h.strip().lower() for h in r.headers["access-control-expose-headers"].split(",")}
    assert exposed >= {"etag", "x-request-id", "x-tile-scale"}, exposed
    pre = client.options(
        url(1, 0, 0),
        headers={
            "origin": "https://x.org",
            "access-control-request-method": "GET",
            "access-control-request-headers": "if-none-match",
        },
    )
    assert pre.status_code == 200
    assert pre.headers["access-control-allow-origin"] == "*"
    assert {m.strip() for m in pre.headers["access-control-allow-methods"].split(",")} >= {"GET", "HEAD"}
    assert "if-none-match" in pre.headers["access-control-allow-headers"].lower()
    assert pre.headers["access-control-max-age"] == "600"


def test_empty_tile_is_204(client):
    r = client.get(url(*tile_for(100.0, -30.0, 12)))
    assert r.status_code == 204 and r.content == b""


def test_placement_matches_lonlat(client):
    """method=original at z16: every decoded vertex lies on the input contour (within two grid units)."""
    z, x, y = tile_for(LON0 + 0.01, LAT0, 15)
    r = client.get(url(z, x, y, "method=original"))
    feats = check_tile(r.content)
    src = client.get("/simplify?scale=1000&method=original&dataset=hills").json()["features"]
    lines = shapely.MultiLineString([f["geometry"]["coordinates"] for f in src])
    unit_deg = 360 / 2**z / 4096
    for f in feats:
        for line in lines_of(f["geometry"]):
            for gx, gy in line[::5]:
                lon, lat = grid_to_lonlat(z, x, y, gx, gy)
                if not (0 <= gx <= 4096 and 0 <= gy <= 4096):
                    continue
                assert lines.distance(shapely.Point(lon, lat)) < 2 * unit_deg


def test_t_zero_at_and_above_source_scale(client):
    z_source = float(zoom_for_scale(50_000, LAT0))
    z = int(np.ceil(z_source)) + 1
    feats = check_tile(client.get(url(*tile_for(LON0, LAT0, z))).content)
    assert feats and all(f["properties"]["t"] == 0.0 for f in feats)


def test_fractional_zoom_between(client):
    z, x, y = tile_for(LON0, LAT0, 10)
    t = {}
    for zoom in (10.0, 10.5, 10.99):
        feats = check_tile(client.get(url(z, x, y, f"zoom={zoom}")).content)
        t[zoom] = {f["id"]: f["properties"]["t"] for f in feats}
    common = set(t[10.0]) & set(t[10.5]) & set(t[10.99])
    assert common
    for fid in common:
        assert t[10.0][fid] >= t[10.5][fid] >= t[10.99][fid]
    assert any(t[10.0][f] > t[10.99][f] for f in common)


def test_pinned_t(client):
    feats = check_tile(client.get(url(*tile_for(LON0, LAT0, 12), "t=0.75")).content)
    assert {f["properties"]["t"] for f in feats} == {0.75}


@pytest.mark.parametrize("method", ["ccsm", "dp", "vw", "wm", "original"])
def test_every_method_renders(client, method):
    r = client.get(url(*tile_for(LON0, LAT0, 11), f"method={method}"))
    assert r.status_code == 200
    assert check_tile(r.content)


WEB_MERCATOR_HALF = 20037508.342789244


def tile_bounds_3857(z, x, y):
    size = 2 * WEB_MERCATOR_HALF / 2**z
    return -WEB_MERCATOR_HALF + x * size, WEB_MERCATOR_HALF - (y + 1) * size, size


def own_line(method, rec, t, scale, to_3857):
    """The method's own line of a stored contour (EPSG:3857), computed here from the stored rows."""
    if method == "ccsm":
        return (1 - t) * rec.base + t * rec.top
    if method == "original":
        return rec.original
    # The service caches baselines per 1/16 of a zoom level: it runs them at the scale rounded to that step.
    snapped = 2.0 ** (round(math.log2(scale) * 16) / 16)
    line = np.asarray(simplify_at_scale(method, rec.original_w, rec.closed, snapped))
    return to_3857(np.vstack([line, line[:1]]) if rec.closed else line)


def feature_points(feature):
    return np.array([p for line in lines_of(feature["geometry"]) for p in line], dtype=float)


@pytest.mark.parametrize("zoom", [11, 12])
def test_each_method_draws_its_own_simplification(client, zoom):
    """Each method's tile is that method's own line of every contour, quantised to the tile grid: a router that
    served one method for another fails here."""
    z, x, y = tile_for(LON0 + 0.01, LAT0, zoom)
    minx, miny, size = tile_bounds_3857(z, x, y)
    k = EXTENT / size
    store = client.app.state.service.store
    info = store.dataset("hills")
    tr = pyproj.Transformer.from_crs(info.working_crs, "EPSG:3857", always_xy=True)

    def to_3857(xy):
        return np.column_stack(tr.transform(xy[:, 0], xy[:, 1]))

    lat = grid_to_lonlat(z, x, y, EXTENT / 2, EXTENT / 2)[1]
    scale = 279_541_132.014 * math.cos(math.radians(lat)) / 2**zoom
    drawn = {}
    for method in ("ccsm", "dp", "wm", "vw", "original"):
        r = client.get(url(z, x, y, f"method={method}"))
        assert r.status_code == 200
        assert float(r.headers["x-tile-scale"]) == pytest.approx(scale, rel=1e-6)
        feats = check_tile(r.content)
        assert len(feats) > 5
        recs = {rec.fid: rec for rec in store.load([f["id"] for f in feats])}
        drawn[method] = {}
        for f in feats:
            rec = recs[f["id"]]
            assert f["properties"]["elevation"] == rec.elevation
            line = own_line(method, rec, f["properties"]["t"], scale, to_3857)
            expected = np.column_stack([np.rint((line[:, 0] - minx) * k), np.rint((miny + size - line[:, 1]) * k)])
            got = feature_points(f)
            drawn[method][f["id"]] = got
            on_edge = ((got == -BUFFER) | (got == EXTENT + BUFFER)).any(axis=1)
            vertices = got[~on_edge]  # the others are where clipping cut the line at the buffer's edge
            # every drawn vertex is a vertex of the method's own line, or (in a tile snap-rounded because plain
            # rounding crossed, issue 13) the centre of a grid pixel the line passes through ...
            gap = np.abs(vertices[:, None, :] - expected[None, :, :]).max(axis=2).min(axis=1)
            exact = np.column_stack([(line[:, 0] - minx) * k, (miny + size - line[:, 1]) * k])
            own = shapely.LineString(exact) if len(exact) >= 2 else shapely.Point(exact[0])
            off_line = shapely.distance(own, shapely.points(vertices[gap > 1].astype(float)))
            assert np.all(off_line <= math.sqrt(2) / 2 + 1e-9), (method, f["id"], gap.max())
            # ... and every vertex of that line inside the tile lies on the drawn line (rows thinned away by
            # significance move it by under half a grid unit, rounding by another).
            inside = expected[((expected >= 0) & (expected <= EXTENT)).all(axis=1)]
            parts = shapely.MultiLineString([line for line in lines_of(f["geometry"])])
            if len(inside):
                far = shapely.distance(parts, shapely.points(inside)).max()
                assert far <= 1.5, (method, f["id"], far)
            if method in ("dp", "wm", "vw"):  # baselines keep every row: exactly the line's vertices
                in_buffer = expected[((expected > -BUFFER) & (expected < EXTENT + BUFFER)).all(axis=1)]
                assert {tuple(p) for p in vertices} == {tuple(p) for p in in_buffer}, (method, f["id"])
    # The methods differ in this tile, so the five tiles differ.
    names = list(drawn)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            common = set(drawn[a]) & set(drawn[b])
            assert any(
                drawn[a][fid].shape != drawn[b][fid].shape or (drawn[a][fid] != drawn[b][fid]).any()
                for fid in common
            ), (a, b)


def test_small_contours_vanish(client):
    """At a small scale the smallest rings are gone; at the source scale they are all there."""
    total = client.get("/datasets/hills").json()["counts"]["contours"]
    near = check_tile(client.get(url(*tile_for(LON0, LAT0, 11))).content)
    far = decode(client.get(url(*tile_for(LON0, LAT0, 6))).content)["contours"]["features"]
    assert 0 < len(far) < len(near) <= total
    assert min(f["properties"]["elevation"] for f in far) < 420  # the big outer rings and lines stay


def test_feature_ids_stable_across_zooms(client):
    parent = {
        f["id"]: f["properties"]["elevation"]
        for f in check_tile(client.get(url(*tile_for(LON0, LAT0, 12))).content)
    }
    child = {
        f["id"]: f["properties"]["elevation"]
        for f in check_tile(client.get(url(*tile_for(LON0, LAT0, 13))).content)
    }
    # The z13 tile lies inside the z12 one: the contours it shows are the parent's, under the same ids.
    shared = set(parent) & set(child)
    assert len(child) > 5 and len(shared) >= 0.8 * len(child), (sorted(parent), sorted(child))
    assert all(parent[fid] == child[fid] for fid in shared)


def test_tilejson(client):
    r = client.get("/tiles/hills/tilejson.json?method=dp")
    assert r.status_code == 200
    tj = r.json()
    assert tj["tilejson"] == "3.0.0"
    (template,) = tj["tiles"]
    assert "/tiles/hills/{z}/{x}/{y}.mvt?" in template
    assert "method=dp" in template and f"v={tj['data_version']}" in template
    w, s, e, n = tj["bounds"]
    assert w < LON0 < e and s < LAT0 < n
    assert tj["minzoom"] == 0 and tj["maxzoom"] == 16
    assert tj["center"][2] >= tj["minzoom"]
    layer, labels = tj["vector_layers"]
    assert layer["id"] == "contours"
    assert set(layer["fields"]) == {"elevation", "index", "t", "level", "rank", "fade_zoom", "hide_zoom"}
    assert labels["id"] == "contour_labels"
    assert set(labels["fields"]) == {
        "elevation", "label", "angle", "level", "rank", "fade_zoom", "hide_zoom", "min_zoom"
    }


def test_raw_gzip_bytes_are_valid(client):
    path = url(*tile_for(LON0, LAT0, 13))
    # iter_raw gives the body as sent, before httpx's lenient decoder (which ignores a missing gzip trailer).
    with client.stream("GET", path, headers={"accept-encoding": "gzip"}) as r:
        raw = b"".join(r.iter_raw())
    assert r.status_code == 200 and r.headers["content-encoding"] == "gzip"
    assert int(r.headers["content-length"]) == len(raw)
    assert raw[:2] == b"\x1f\x8b"
    body = gzip.decompress(raw)  # strict: checks the CRC and length trailer
    plain = client.get(path, headers={"accept-encoding": "identity"})
    assert body == plain.content
    assert len(check_tile(body)) > 5
