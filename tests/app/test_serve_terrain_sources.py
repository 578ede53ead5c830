"""``ccsm serve`` of a terrain tile pyramid and a GeoTIFF URL, as a user runs it: a Terrarium pyramid cut from a
real DEM (Maunga Whau) served by an HTTP server on loopback, a real server built from it at startup, its tiles
over HTTP; a bad URL fails its own dataset only; a restart rebuilds nothing (the source's key is its text and
options, not a file's bytes); a source written wrongly is refused by the command and named by the service."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np
import pytest
import rasterio
from range_server import serve_folder
from real_dems import MAUNGA_WHAU_ASC
from support.mvt import decode_served
from support.server import wait_ready as build_ended
from terrain_pyramids import Pyramid, write_pyramid
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.io.dem import contours_from_dem, read_dem
from engine.io.terrain_tiles import ENCODINGS, TerrainTiles
from tests.app.conftest import LiveServer
from tests.app.helpers import tile_for

_register_commands()

TERRARIUM = ENCODINGS["terrarium"]


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory: pytest.TempPathFactory) -> Pyramid:
    grid = read_dem(MAUNGA_WHAU_ASC)
    return write_pyramid(
        tmp_path_factory.mktemp("pyramid"),
        grid.z.filled(np.nan),
        rasterio.Affine(*grid.transform),
        "EPSG:2193",
        zoom=16,
        encoding=TERRARIUM,
    )


def bbox_text(pyramid: Pyramid) -> str:
    return ",".join(f"{v:.6f}" for v in pyramid.bbox)


def test_serve_builds_a_tile_pyramid_at_startup_and_serves_its_tiles(tmp_path: Path, pyramid: Pyramid) -> None:
    store = tmp_path / "ccsm.sqlite"
    with serve_folder(pyramid.root) as tiles:
        template = f"terrarium:{tiles.url}/{{z}}/{{x}}/{{y}}.png"
        env = {"CCSM_STORE_PATH": str(store), "CCSM_BUILD_WORKERS": "1"}
        args = [
            template,
            "http://127.0.0.1:9/missing.tif",
            "--bbox",
            bbox_text(pyramid),
            "--dem-zoom",
            "16",
            "--interval",
            "10",
        ]
        server = LiveServer(env, args, log=tmp_path / "first.log")
        try:
            server.wait_healthy()
            ready = server.wait_ready("tiles-z16")
            with httpx.Client(base_url=server.url, timeout=10) as client:
                failed = build_ended(client, "missing")
            fetched = tiles.count(".png")
            features = served_contours(server.url, "tiles-z16", pyramid)
        finally:
            server.stop()
        # The same contours as the pyramid read directly (the reader ccsm build uses).
        bbox = tuple(float(v) for v in bbox_text(pyramid).split(","))
        direct = contours_from_dem(TerrainTiles(TERRARIUM, template.split(":", 1)[1], bbox, 16), interval=10.0)
        assert ready["counts"]["contours"] == len(direct.contours) > 10
        assert ready["source"] == template
        assert fetched >= len(pyramid.tiles)
        levels = {f["properties"]["elevation"] for f in features}
        assert levels and all(level % 10 == 0 for level in levels) and max(levels) >= 180
        # A GeoTIFF URL that does not answer fails its own dataset, with the reason; the service served anyway.
        assert failed["state"] == "failed"
        assert "http://127.0.0.1:9/missing.tif" in failed["build"]["error"]
        assert "cannot read DEM" in failed["build"]["error"]

        # Restart with the same source from CCSM_SOURCES (and one written wrongly): nothing is fetched or rebuilt.
        env = {
            **env,
            "CCSM_SOURCES": json.dumps([template, "terrain:http://127.0.0.1:9/{z}/{x}/{y}.png"]),
            "CCSM_BBOX": bbox_text(pyramid),
            "CCSM_DEM_ZOOM": "16",
            "CCSM_INTERVAL": "10",
        }
        before = tiles.count(".png")
        again = LiveServer(env, log=tmp_path / "second.log")
        try:
            again.wait_healthy()
            current = again.wait_ready("tiles-z16")
            with httpx.Client(base_url=again.url, timeout=10) as client:
                wrong = build_ended(client, "source")
        finally:
            again.stop()
        assert current["data_version"] == ready["data_version"]
        assert tiles.count(".png") == before
    assert wrong["state"] == "failed"
    assert "unknown terrain tile encoding 'terrain'" in wrong["build"]["error"]


def served_contours(url: str, dataset: str, pyramid: Pyramid) -> list[dict]:
    """The contour features of the z14 tiles over the middle of the pyramid's area."""
    west, south, east, north = pyramid.bbox
    z, x, y = tile_for((west + east) / 2, (south + north) / 2, 14)
    out: list[dict] = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            r = httpx.get(f"{url}/tiles/{dataset}/{z}/{x + dx}/{y + dy}.mvt", timeout=30)
            assert r.status_code in (200, 204)
            if r.status_code == 200:
                out += decode_served(r.content).get("contours", {}).get("features", [])
    return out


def test_serve_refuses_a_source_written_wrongly_before_starting(tmp_path: Path, pyramid: Pyramid) -> None:
    runner = CliRunner()
    store = ["--store", str(tmp_path / "s.sqlite")]
    cases = {
        "unknown terrain tile encoding 'terrain'": ["terrain:http://h/{z}/{x}/{y}.png", "--bbox", "1,1,2,2"],
        "needs an area": ["terrarium:http://h/{z}/{x}/{y}.png"],
        "source not found": [str(tmp_path / "nowhere.tif")],
    }
    for message, args in cases.items():
        result = runner.invoke(app, ["serve", *args, *store])
        assert result.exit_code == 2, result.output
        assert message in result.output
