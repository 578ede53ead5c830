"""The service for real: ``ccsm serve`` (uvicorn) on a loopback port, every endpoint over HTTP."""

from __future__ import annotations

import json
import subprocess

import httpx
import pytest
from support.node import NODE_DIR, node_available

from tests.app.conftest import LAT0, LON0, synthetic_features
from tests.app.helpers import check_tile, tile_for


def test_endpoints_over_loopback(live):
    base = live.url
    assert httpx.get(base + "/healthz").json()["status"] == "ok"
    assert [d["id"] for d in httpx.get(base + "/datasets").json()] == ["hills"]
    assert httpx.get(base + "/datasets/hills").json()["state"] == "ready"
    tj = httpx.get(base + "/tiles/hills/tilejson.json").json()
    template = tj["tiles"][0]
    assert template.startswith(base)
    z, x, y = tile_for(LON0, LAT0, 12)
    r = httpx.get(template.format(z=z, x=x, y=y), headers={"accept-encoding": "gzip"})
    assert r.status_code == 200 and r.headers["content-encoding"] == "gzip"
    check_tile(r.content)
    assert (
        httpx.get(template.format(z=z, x=x, y=y), headers={"if-none-match": r.headers["etag"]}).status_code
        == 304
    )
    assert httpx.get(base + "/tiles/hills/12/0/0.mvt").status_code == 204
    doc = httpx.get(base + "/simplify?scale=250000").json()
    assert doc["features"]
    assert httpx.get(base + "/openapi.json").status_code == 200
    assert httpx.get(base + "/docs").status_code == 200
    assert httpx.get(base + "/").status_code == 200


def test_upload_and_delete_over_loopback(live):
    body = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=11)[:3]})
    r = httpx.post(
        live.url + "/datasets?id=live-up", content=body, headers={"content-type": "application/geo+json"}
    )
    assert r.status_code == 202
    live.wait_ready("live-up", timeout=120)
    assert httpx.delete(live.url + "/datasets/live-up").status_code == 204
    big = httpx.post(live.url + "/datasets", content=b"x" * (700 * 1024), headers={"content-type": "application/json"})
    assert big.status_code == 413
    assert httpx.get(live.url + "/healthz").status_code == 200


def test_bad_requests_do_not_hurt_the_server(live):
    for path in [
        "/tiles/hills/40/0/0.mvt",
        "/tiles/hills/2/9/9.mvt",
        "/simplify?scale=nan",
        "/simplify?scale=-1",
        "/tiles/hills/5/1/1.mvt?zoom=7",
        "/tiles/x/1/1/1.mvt",
        "/simplify?scale=5&bbox=3,3,1,1",
    ]:
        r = httpx.get(live.url + path)
        assert 400 <= r.status_code < 500 and r.json()["detail"]
    assert httpx.get(live.url + "/datasets/hills").json()["state"] == "ready"


def test_maplibre_parser_decodes_tiles(live, tmp_path):
    """Tiles decoded by @mapbox/vector-tile (MapLibre's parser) have valid geometry in the right place."""
    if not node_available("@mapbox/vector-tile"):
        pytest.fail("node and tests/app/node/node_modules are required: run `make install` (npm ci in tests/app/node)")
    args = []
    for zoom in (9, 11, 13, 15):
        z, x, y = tile_for(LON0 + 0.005, LAT0 + 0.005, zoom)
        r = httpx.get(f"{live.url}/tiles/hills/{z}/{x}/{y}.mvt")
        assert r.status_code == 200
        path = tmp_path / f"{z}-{x}-{y}.mvt"
        path.write_bytes(r.content)
        args.append(f"{z}/{x}/{y}={path}")
    out = subprocess.run(
        ["node", str(NODE_DIR / "decode.mjs"), *args], capture_output=True, text=True, check=True
    )
    tiles = json.loads(out.stdout)
    assert len(tiles) == 4
    for t in tiles:
        assert t["layers"][0] == "contours" and set(t["layers"]) <= {"contours", "contour_labels"}
        assert t["version"] == 2 and t["extent"] == 4096
        assert t["features"]
        for f in t["features"]:
            assert f["type"] == 2  # LineString
            assert isinstance(f["id"], int)
            # The contract of docs/design.md section 9: the cartography attributes beside elevation, index, t.
            assert set(f["properties"]) == {"elevation", "index", "t", "level", "rank", "fade_zoom", "hide_zoom"}
            for line in f["geometry"]:
                assert len(line) >= 2
                assert all(-64 <= px <= 4160 and -64 <= py <= 4160 for px, py in line)
            coords = f["lonlat"]["coordinates"]
            flat = coords if f["lonlat"]["type"] == "LineString" else [p for part in coords for p in part]
            for lon, lat in flat:
                assert abs(lon - LON0) < 0.12 and abs(lat - LAT0) < 0.1  # where the synthetic hills are
