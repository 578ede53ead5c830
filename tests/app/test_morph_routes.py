"""GET /morph/{dataset}/{z}/{x}/{y}.mvt and its TileJSON: the HTTP contract of morph tiles."""

import math

import pytest
import shapely
from support.mvt import decode

from tests.app.conftest import LAT0, LON0
from tests.app.helpers import EXTENT, lines_of, tile_for

MVT = "application/vnd.mapbox-vector-tile"
#: Tile units by which the start layer may lie from the plain tile of zoom z: both put the same slice on the
#: grid, but the morph tile rounds its start and end ends on their own (one unit in each coordinate).
START_TOLERANCE = math.sqrt(2.0)


def inside_tile(geometry: dict) -> shapely.Geometry:
    """A feature's lines within the tile square (the buffers beyond it are cut on their own terms)."""
    lines = shapely.MultiLineString([[tuple(p) for p in line] for line in lines_of(geometry)])
    return shapely.clip_by_rect(lines, 0, 0, EXTENT, EXTENT)


def morph_url(z, x, y):
    return f"/morph/hills/{z}/{x}/{y}.mvt"


def test_morph_tile_has_both_layers_with_the_same_features(client):
    r = client.get(morph_url(*tile_for(LON0, LAT0, 11)))
    assert r.status_code == 200
    assert r.headers["content-type"] == MVT
    layers = decode(r.content)
    start, end = layers["contours"]["features"], layers["contours_end"]["features"]
    assert len(start) > 5
    assert [f["id"] for f in start] == [f["id"] for f in end]
    for f in start:
        props = f["properties"]
        assert {"elevation", "index", "t", "min_zoom"} <= set(props)
        samples = [props["t"]] + [props[f"t{k}"] for k in range(1, 9)]
        assert all(a >= b for a, b in zip(samples, samples[1:], strict=False))  # t falls as the zoom rises
    assert all(f["properties"] == {} for f in end)


def test_the_start_layer_is_the_tile_of_zoom_z(client):
    z, x, y = tile_for(LON0, LAT0, 12)
    morph = decode(client.get(morph_url(z, x, y)).content)["contours"]["features"]
    plain = decode(client.get(f"/tiles/hills/{z}/{x}/{y}.mvt").content)["contours"]["features"]
    drawn_at_z = {f["id"]: f for f in morph if f["properties"]["min_zoom"] < z}
    assert {f["id"] for f in plain} <= set(drawn_at_z)
    worst = 0.0
    for f in plain:
        start = drawn_at_z[f["id"]]
        assert start["properties"]["t"] == f["properties"]["t"]
        assert start["properties"]["elevation"] == f["properties"]["elevation"]
        want, got = inside_tile(f["geometry"]), inside_tile(start["geometry"])
        assert want.is_empty == got.is_empty, f["id"]
        if not want.is_empty:
            worst = max(worst, shapely.hausdorff_distance(want, got))
    assert worst <= START_TOLERANCE, f"the start layer lies {worst:.2f} tile units from the tile of zoom {z}"


def test_morph_etag_and_gzip(client):
    path = morph_url(*tile_for(LON0, LAT0, 11))
    r = client.get(path, headers={"accept-encoding": "gzip"})
    assert r.headers["content-encoding"] == "gzip"
    again = client.get(path, headers={"if-none-match": r.headers["etag"], "accept-encoding": "gzip"})
    assert again.status_code == 304
    plain = client.get(path, headers={"accept-encoding": "identity"})
    assert plain.headers["etag"] != r.headers["etag"] and plain.content == r.content


@pytest.mark.parametrize(
    ("path", "status"),
    [
        ("/morph/hills/{z}/{x}/{y}.mvt", 204),  # a tile far from the data
        ("/morph/hills/17/0/0.mvt", 404),  # above the served zooms
        ("/morph/hills/3/8/0.mvt", 404),  # outside the tile matrix
        ("/morph/nope/3/0/0.mvt", 404),
    ],
)
def test_morph_errors_and_empty(client, path, status):
    z, x, y = tile_for(100.0, -30.0, 12)
    r = client.get(path.format(z=z, x=x, y=y))
    assert r.status_code == status
    if status == 404:
        assert r.json()["detail"]


def test_morph_tilejson(client):
    body = client.get("/morph/hills/tilejson.json").json()
    assert body["tilejson"] == "3.0.0"
    assert "/morph/hills/{z}/{x}/{y}.mvt?" in body["tiles"][0]
    assert [layer["id"] for layer in body["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert {"t1", "t8", "min_zoom"} <= set(body["vector_layers"][0]["fields"])
    assert body["ccsm_morph"] == {
        "version": 1,
        "t_samples": 8,
        "start_layer": "contours",
        "end_layer": "contours_end",
    }
