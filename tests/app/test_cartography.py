"""Issue 11 over HTTP: tile attributes and the zoom rule, labels that hold still, TileJSON, /simplify and the
CLI dropping faded levels, and a GeoPackage in feet served in feet by a real server."""

from __future__ import annotations

import html
import json
import math
import time
from pathlib import Path

import httpx
import numpy as np
import pyogrio.raw
import pytest
import shapely
from helpers import EXTENT, check_tile, grid_to_lonlat, tile_for
from support.mvt import decode
from support.server import wait_ready
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.cartography.labels import UPSIDE_DOWN_LIMIT_DEG
from engine.store.store import CCSStore
from tests.app.conftest import LAT0, LON0, LiveServer, synthetic_features

_register_commands()

#: The synthetic hills' elevations (metres): rings 400..620 by 20, open lines at 380 and 360.
ELEVATIONS = [float(f["properties"]["elevation"]) for f in synthetic_features()]


def tiles_over(bounds: list[float], z: int) -> list[tuple[int, int, int]]:
    w, s, e, n = bounds
    _, x0, y0 = tile_for(w, n, z)
    _, x1, y1 = tile_for(e, s, z)
    return [(z, x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]


def labels_at(get, base: str, bounds: list[float], z: int) -> list[tuple[int, float, float, dict]]:
    """Every label of every tile of zoom z over the bounds: (contour id, lon, lat, properties)."""
    out = []
    for z_, x, y in tiles_over(bounds, z):
        r = get(f"{base}/{z_}/{x}/{y}.mvt")
        if r.status_code == 204:
            continue
        for f in decode(r.content).get("contour_labels", {}).get("features", []):
            gx, gy = f["geometry"]["coordinates"]
            assert 0 <= gx < EXTENT and 0 <= gy < EXTENT  # each label in exactly one tile per zoom
            lon, lat = grid_to_lonlat(z_, x, y, gx, gy)
            out.append((f["id"], lon, lat, f["properties"]))
    return out


def test_a_tile_of_zoom_z_holds_a_level_iff_its_hide_zoom_is_below_z_plus_1(client):
    tj = client.get("/tiles/hills/tilejson.json").json()
    schedule = tj["ccsm_cartography"]["schedule"]
    hide0 = schedule[0]["hide_zoom"]  # the 20 m levels (rank 0): 1:250,000 at about 36.6° N
    assert 9 < hide0 < 10
    for z in range(6, 14):
        feats = check_tile(client.get("/tiles/hills/{}/{}/{}.mvt".format(*tile_for(LON0, LAT0, z))).content)
        ranks = {f["properties"]["rank"] for f in feats}
        for f in feats:
            p = f["properties"]
            assert p["hide_zoom"] < z + 1
            assert p["level"] == (1 if p["elevation"] % 100 == 0 else 0) and p["index"] == (p["level"] == 1)
            assert p["rank"] == (0 if p["elevation"] % 100 else 1 if p["elevation"] % 200 else 2)
        # rank 0 is in the tile of the zoom its fade ends in, and in no tile further out
        assert (0 in ranks) == (z >= math.floor(hide0)), (z, ranks)
        assert ranks - {0}  # coarser ranks stay


def test_labels_hold_still_from_one_zoom_to_the_next(client):
    bounds = client.get("/tiles/hills/tilejson.json").json()["bounds"]
    seen = {}
    for z in (12, 13, 14):
        labels = labels_at(client.get, "/tiles/hills", bounds, z)
        for *_, p in labels:
            assert p["elevation"] % 100 == 0 and p["label"] == f"{p['elevation']:g} m"
            # upright, or turned uphill by the neighbouring levels, never past the upside-down limit
            assert abs(p["angle"]) <= UPSIDE_DOWN_LIMIT_DEG and p["min_zoom"] < z + 1
        seen[z] = labels
    assert seen[14], "no labels on the hills at z14"
    for z in (12, 13):
        grid_deg = 360 / 2**z / EXTENT  # one grid unit of zoom z
        for fid, lon, lat, _ in seen[z]:  # every label shown at z is at z + 1, in the same place
            near = [
                (lon2, lat2)
                for fid2, lon2, lat2, _ in seen[z + 1]
                if fid2 == fid and abs(lon2 - lon) <= grid_deg and abs(lat2 - lat) <= grid_deg
            ]
            assert near, (z, fid, lon, lat)
    # morph tiles carry the same labels
    morph = labels_at(client.get, "/morph/hills", bounds, 14)
    assert sorted((f, round(a, 7), round(b, 7)) for f, a, b, _ in morph) == sorted(
        (f, round(a, 7), round(b, 7)) for f, a, b, _ in seen[14]
    )


def test_tilejson_lists_both_layers_and_the_cartography(client):
    tj = client.get("/tiles/hills/tilejson.json").json()
    layers = {layer["id"]: set(layer["fields"]) for layer in tj["vector_layers"]}
    assert layers["contours"] >= {"elevation", "index", "t", "level", "rank", "fade_zoom", "hide_zoom"}
    assert layers["contour_labels"] >= {"elevation", "label", "angle", "level", "rank", "fade_zoom", "hide_zoom"}
    carto = tj["ccsm_cartography"]
    assert (carto["units"], carto["index_every"], carto["base_interval"], carto["attribute_names"]) == (
        "m",
        5,
        20.0,
        "ccsm",
    )
    assert [r["step"] for r in carto["schedule"]] == [20.0, 100.0, 200.0]
    assert carto["schedule"][0]["fade_scale"] == 50_000 and carto["schedule"][0]["hide_scale"] == 250_000
    assert tj["version"] == f"1.{tj['data_version']}.0"
    assert tj["attribution"] == "Contours: ccsm, from hills.geojson"
    morph = client.get("/morph/hills/tilejson.json").json()
    assert [layer["id"] for layer in morph["vector_layers"]] == ["contours", "contours_end", "contour_labels"]
    assert morph["ccsm_cartography"] == carto


def test_simplify_leaves_out_the_levels_faded_at_that_scale(client):
    n_fine = sum(1 for e in ELEVATIONS if e % 100)  # the 20 m levels, faded out at 1:250,000 and beyond
    some = client.get("/simplify", params={"dataset": "hills", "scale": 300_000}).json()
    every = client.get("/simplify", params={"dataset": "hills", "scale": 300_000, "all_levels": "true"}).json()
    assert some["dropped"] == n_fine and every["dropped"] == 0
    assert all(f["properties"]["elevation"] % 100 == 0 for f in some["features"])
    assert {f["properties"]["level"] for f in some["features"]} == {1}
    assert len(every["features"]) > len(some["features"])
    near = client.get("/simplify", params={"dataset": "hills", "scale": 100_000}).json()
    assert near["dropped"] == 0  # still fading in, not gone


def test_ccsm_simplify_reports_and_writes_the_dropped_count(tmp_path, synthetic_path):
    out = tmp_path / "s.geojson"
    runner = CliRunner()
    args = ["simplify", str(synthetic_path), "--scale", "300000", "-o", str(out), "--workers", "1"]
    result = runner.invoke(app, [*args, "--store", str(tmp_path / "cache.sqlite")])
    assert result.exit_code == 0, result.output
    n_fine = sum(1 for e in ELEVATIONS if e % 100)
    assert f"{n_fine} dropped" in result.stdout.replace("\n", " ")
    assert json.loads(out.read_text())["dropped"] == n_fine
    bad = runner.invoke(app, [*args, "--store", str(tmp_path / "cache.sqlite"), "--schedule", "20:1e5,30"])
    assert bad.exit_code == 2 and "schedule entry 2 '30'" in bad.output.replace("\n", " ")


@pytest.mark.parametrize(
    ("schedule", "message"),
    [
        ("50:1e5,100", "schedule entry 1: step 50 must divide the data's interval 20 m"),
        ("20:40000,100", "schedule entry 1: hide scale 40000 must be larger than the source scale 50000"),
    ],
)
def test_ccsm_simplify_refuses_a_schedule_that_does_not_fit_the_data_before_building(
    tmp_path, synthetic_path, schedule, message
):
    cache = tmp_path / "cache.sqlite"
    args = ["simplify", str(synthetic_path), "-o", str(tmp_path / "s.geojson"), "--workers", "1"]
    result = CliRunner().invoke(app, [*args, "--store", str(cache), "--schedule", schedule])
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split())
    assert not (tmp_path / "s.geojson").exists()
    # Refused before the build: nothing kept in the cache (no dataset, no build under way or failed).
    store = CCSStore(cache)
    assert store.dataset_ids() == [] and store.build_statuses() == {}


# -- a GeoPackage in feet, served by a real server -------------------------------------------------------


def write_feet_gpkg(path: Path, shift_ft: float = 0.0) -> Path:
    """The synthetic hills with heights in feet (2 ft per metre of the original, 40 ft interval) in an
    ``ELEV_FT`` attribute."""
    feats = synthetic_features()
    geoms = np.array([shapely.to_wkb(shapely.LineString(f["geometry"]["coordinates"])) for f in feats], dtype=object)
    elev = np.array([2.0 * f["properties"]["elevation"] + shift_ft for f in feats])
    ids = np.array([f["properties"]["id"] for f in feats], dtype=object)
    pyogrio.raw.write(
        path, geoms, [elev, ids], ["ELEV_FT", "id"], driver="GPKG", geometry_type="LineString", crs="EPSG:4326"
    )
    return path


@pytest.fixture(scope="module")
def feet_server(tmp_path_factory):
    d = tmp_path_factory.mktemp("feet")
    src = write_feet_gpkg(d / "feet.gpkg")
    env = {
        "CCSM_STORE_PATH": str(d / "ccsm.sqlite"),
        "CCSM_SOURCES": str(src),
        "CCSM_ELEVATION_FIELD": "ELEV_FT",
        "CCSM_BUILD_WORKERS": "1",
        "CCSM_ATTRIBUTION": 'USGS <3DEP> & "friends"',
    }
    server = LiveServer(env, log=d / "server.log")
    try:
        server.wait_healthy()
        server.wait_ready("feet")
        yield server, env, src, d
    finally:
        server.stop()


def test_a_geopackage_in_feet_comes_out_in_feet(feet_server):
    server, *_ = feet_server
    tj = httpx.get(f"{server.url}/tiles/feet/tilejson.json").json()
    carto = tj["ccsm_cartography"]
    assert carto["units"] == "ft" and carto["base_interval"] == 40.0
    assert [r["step"] for r in carto["schedule"]] == [40.0, 200.0]  # the feet series: 40 ft, index 200 ft
    assert "ft" in tj["vector_layers"][0]["fields"]["elevation"]
    labels = labels_at(lambda u: httpx.get(server.url + u), "/tiles/feet", tj["bounds"], 14)
    assert labels and all(p["label"] == f"{p['elevation']:g} ft" for *_, p in labels)
    assert {p["elevation"] for *_, p in labels} <= {800.0, 1000.0, 1200.0}


def test_tilejson_attribution_is_escaped_and_version_follows_the_data(feet_server, tmp_path):
    server, env, src, d = feet_server
    before = httpx.get(f"{server.url}/tiles/feet/tilejson.json").json()
    assert before["attribution"] == html.escape('USGS <3DEP> & "friends"')
    assert "<" not in before["attribution"] and "&amp;" in before["attribution"]
    server.stop()
    write_feet_gpkg(src, shift_ft=40.0)  # the data changes: every contour 40 ft higher
    again = LiveServer(env, log=d / "server2.log")
    try:
        again.wait_healthy()
        deadline = time.monotonic() + 180
        while again.wait_ready("feet")["data_version"] == before["data_version"] and time.monotonic() < deadline:
            time.sleep(0.5)  # the old version is served while the changed source is rebuilt
        after = httpx.get(f"{again.url}/tiles/feet/tilejson.json").json()
    finally:
        again.stop()
    assert after["data_version"] > before["data_version"]
    assert after["version"] != before["version"]


# -- options per dataset, given with an upload ---------------------------------------------------------------


def test_upload_options_name_the_elevation_ele_and_set_units_and_schedule(client):
    body = json.dumps({"type": "FeatureCollection", "features": synthetic_features()})
    headers = {"content-type": "application/geo+json"}
    query = "id=mc&attribute_names=maplibre-contour&units=ft&schedule=20:60000,100:90000,200&attribution=Me%20%3CI%3E"
    r = client.post(f"/datasets?{query}", content=body, headers=headers)
    assert r.status_code == 202, r.text
    assert wait_ready(client, "mc")["state"] == "ready"
    tj = client.get("/tiles/mc/tilejson.json").json()
    carto = tj["ccsm_cartography"]
    assert (carto["units"], carto["attribute_names"]) == ("ft", "maplibre-contour")
    assert [(k["step"], k["hide_scale"]) for k in carto["schedule"]] == [(20, 60_000), (100, 90_000), (200, None)]
    assert tj["attribution"] == "Me &lt;I&gt;"
    assert {"ele", "level"} <= set(tj["vector_layers"][0]["fields"]) and "elevation" not in tj["vector_layers"][0][
        "fields"
    ]
    feats = decode(client.get("/tiles/mc/{}/{}/{}.mvt".format(*tile_for(LON0, LAT0, 13))).content)["contours"][
        "features"
    ]
    assert feats and all("ele" in f["properties"] and "elevation" not in f["properties"] for f in feats)
    labels = labels_at(client.get, "/tiles/mc", tj["bounds"], 14)
    assert labels and all(p["label"] == f"{p['ele']:g} ft" for *_, p in labels)


@pytest.mark.parametrize(
    ("query", "where"),
    [
        ("schedule=20:1e5,30", "schedule entry 2 '30'"),
        ("schedule=50:1e5,100", "schedule entry 1: step 50 must divide the data's interval 20 m"),
        ("schedule=20:4e4,100:2e5,200", "schedule entry 1: hide scale 40000 must be larger than the source scale"),
        ("units=yards", "units"),
        ("index_every=1", "index_every"),
    ],
)
def test_bad_upload_options_get_a_4xx_naming_them(client, query, where):
    body = json.dumps({"type": "FeatureCollection", "features": synthetic_features()[:4]})
    r = client.post(f"/datasets?id=bad&{query}", content=body, headers={"content-type": "application/geo+json"})
    assert 400 <= r.status_code < 500 and where in r.text, (r.status_code, r.text)
    if "schedule" in query:  # a schedule that does not fit the data: refused at once, with a JSON reason
        assert r.status_code == 400 and where in r.json()["detail"], r.text
    # Nothing was kept: no dataset, no upload file.
    assert client.get("/datasets/bad").status_code == 404
    assert list(Path(client.app.state.service.upload_dir).glob("*.geojson")) == []
