"""style.json, glyphs and hillshade tiles over HTTP from a real server: a DEM dataset (a synthetic GeoTIFF,
shaded) beside a contour dataset without a DEM."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image
from synthetic_rasters import fractal_heights, write_geotiff

from tests.app.conftest import LAT0, LON0, LiveServer
from tests.app.helpers import tile_for

REPO = Path(__file__).resolve().parents[2]
VALIDATOR = REPO / "web" / "node_modules" / "@maplibre" / "maplibre-gl-style-spec" / "dist" / "gl-style-validate.mjs"
FONT = "DejaVu Sans Book"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, synthetic_path: Path) -> Iterator[LiveServer]:
    """A server with ``terrain`` (a 48 x 48 GeoTIFF DEM of 90 m cells at LON0, LAT0) and ``hills`` (contours)."""
    d = tmp_path_factory.mktemp("styles")
    # 90 m cells in degrees near LAT0, so the DEM covers about 4.3 km around the synthetic hills.
    cell = 90 / 111_320 / np.cos(np.radians(LAT0))
    dem = write_geotiff(
        d / "terrain.tif",
        fractal_heights(seed=3, beta=3.0, n=48, relief_m=200.0).astype(np.float32),
        west=LON0 - 24 * cell,
        north=LAT0 + 24 * cell,
        cell=cell,
        crs="EPSG:4326",
    )
    srv = LiveServer(
        {
            "CCSM_STORE_PATH": str(d / "store.sqlite"),
            "CCSM_SOURCES": f"{dem},{synthetic_path}",
            "CCSM_INTERVAL": "20",
            "CCSM_BUILD_WORKERS": "1",
        },
        log=d / "server.log",
    )
    try:
        srv.wait_healthy()
        srv.wait_ready("terrain", timeout=300)
        srv.wait_ready("hills", timeout=300)
        yield srv
    finally:
        srv.stop()


def test_hillshade_tile_of_a_dem_dataset(server):
    z, x, y = tile_for(LON0, LAT0, 14)
    r = httpx.get(f"{server.url}/hillshade/terrain/{z}/{x}/{y}.png")
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    img = np.asarray(Image.open(io.BytesIO(r.content)))
    assert img.shape == (256, 256, 4)
    assert (img[..., 3] == 255).mean() > 0.9  # the DEM covers this tile
    assert img[..., 0].std() > 5  # relief, not a flat grey
    again = httpx.get(f"{server.url}/hillshade/terrain/{z}/{x}/{y}.png", headers={"if-none-match": r.headers["etag"]})
    assert again.status_code == 304


def test_hillshade_off_the_dem_is_204_and_without_a_dem_404(server):
    z, x, y = tile_for(LON0 + 1.0, LAT0, 14)
    assert httpx.get(f"{server.url}/hillshade/terrain/{z}/{x}/{y}.png").status_code == 204
    z, x, y = tile_for(LON0, LAT0, 14)
    r = httpx.get(f"{server.url}/hillshade/hills/{z}/{x}/{y}.png")
    assert r.status_code == 404
    assert "'hills' has no DEM" in json.dumps(r.json())
    assert httpx.get(f"{server.url}/hillshade/terrain/3/9/9.png").status_code == 404


def test_glyphs_are_served_and_bad_requests_say_why(server):
    r = httpx.get(f"{server.url}/fonts/{FONT}/0-255.pbf")
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-protobuf"
    assert FONT.encode() in r.content[:64] and len(r.content) > 20_000
    # MapLibre asks for a whole stack joined by commas: the served font anywhere in it is enough.
    assert httpx.get(f"{server.url}/fonts/Open Sans Regular,{FONT}/0-255.pbf").content == r.content
    unknown = httpx.get(f"{server.url}/fonts/Comic Sans/0-255.pbf")
    assert unknown.status_code == 404 and "'Comic Sans' is not served" in unknown.text
    bad = httpx.get(f"{server.url}/fonts/{FONT}/0-10.pbf")
    assert bad.status_code == 400 and "glyph range 0-10" in bad.text
    assert httpx.get(f"{server.url}/fonts/{FONT}/zero.pbf").status_code == 400


def test_style_of_a_dem_dataset_has_hillshade_and_every_url_resolves(server):
    style = httpx.get(f"{server.url}/styles/terrain/style.json").json()
    assert [layer["id"] for layer in style["layers"]][:2] == ["background", "hillshade"]
    tilejson_url = style["sources"]["ccsm-contours"]["url"]
    assert tilejson_url == f"{server.url}/tiles/terrain/tilejson.json"
    tilejson = httpx.get(tilejson_url).json()
    ranks = {entry["rank"] for entry in tilejson["ccsm_cartography"]["schedule"]}
    assert {layer["id"] for layer in style["layers"] if layer["type"] == "line"} == {
        f"contours-rank-{r}" for r in ranks
    } | {"coastline"}
    glyphs = style["glyphs"].replace("{fontstack}", FONT).replace("{range}", "0-255")
    assert httpx.get(glyphs).status_code == 200
    z, x, y = tile_for(LON0, LAT0, 13)
    hillshade = style["sources"]["ccsm-hillshade"]["tiles"][0].format(z=z, x=x, y=y)
    assert httpx.get(hillshade).status_code == 200


def test_style_of_contours_without_a_dem_has_no_hillshade_and_validates(server, tmp_path):
    r = httpx.get(f"{server.url}/styles/hills/style.json")
    assert r.status_code == 200
    style = r.json()
    assert "ccsm-hillshade" not in style["sources"]
    assert httpx.get(f"{server.url}/styles/nope/style.json").status_code == 404
    node = shutil.which("node")
    assert node and VALIDATOR.is_file(), "node and web/node_modules (npm ci in web/) are needed"
    path = tmp_path / "style.json"
    path.write_text(r.text)
    result = subprocess.run([node, str(VALIDATOR), str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and not result.stdout.strip(), result.stdout + result.stderr
