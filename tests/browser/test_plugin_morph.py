"""The ccsm-morph plugin (web/plugin) in Chromium: a real mouse-wheel zoom through one level fetches each
morph tile once, asks for nothing while the zoom stays inside the level, draws at least 32 distinct shapes and
never a frame without contours; from the service (the project's page) and from a .pmtiles archive on a static
file server that answers Range requests (written by `ccsm export`), with the tile service stopped, drawn by the
oldest and by the newest MapLibre of the plugin's peer range (a MapLibre 4 page never settles: the range says so).
"""

from __future__ import annotations

import math
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from conftest import REPO, SERVICE_STORES, service_stopped, watched_page
from maplibre_versions import PAGE_MAPLIBRE, install_maplibre, installed_version, peer_range, versions_in_range
from morph_pmtiles import morph_pmtiles_from_service
from morph_probe import install_probe, read_probe, wheel_through_level
from static_server import serve_static

pytestmark = pytest.mark.browser

STEPS = 32  # the plugin's default stepsPerZoom
LAST_STEP = 11 + (STEPS - 1) / STEPS  # the wheel stops on the last step of level 11, short of 12
MIN_SHAPES = 24  # distinct drawn geometries required over the 32 steps (see assert_morphed_through_the_level)
WEB = REPO / "web"
# A small map centred in one z11 tile of the sample (545/800): 32 steps of one tile stay quick on a busy
# machine, and the view keeps that one tile from zoom 11 to 12.
SMALL = {"width": 480, "height": 420}
CENTRE = [-84.1113, 36.5273]


def visible_tiles(page: Any, map_expr: str, z: int) -> set[tuple[int, int]]:
    """(x, y) of the z tiles that cover the map's view (512 px tiles: zoom z shows tiles of zoom z)."""
    w, s, e, n = page.evaluate(
        f"() => {{ const b = {map_expr}.getBounds(); return [b.getWest(), b.getSouth(), b.getEast(), b.getNorth()]; }}"
    )

    def tile(lon: float, lat: float) -> tuple[int, int]:
        r = math.radians(lat)
        return int((lon + 180) / 360 * 2**z), int((1 - math.log(math.tan(r) + 1 / math.cos(r)) / math.pi) / 2 * 2**z)

    (x0, y0), (x1, y1) = tile(w, n), tile(e, s)
    return {(x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)}


def tile_of(url: str) -> tuple[int, int, int]:
    z, x, y = httpx.URL(url).path.removesuffix(".mvt").split("/")[-3:]
    return int(z), int(x), int(y)


def assert_morphed_through_the_level(seen: dict[str, Any]) -> None:
    steps = seen["steps"]
    assert seen["frames"] > 0 and seen["blank"] == 0, seen
    # Every one of the 32 steps of the level was on screen (the start 11.0 and the 31 after it) ...
    assert steps[0] == 11.0 and steps[-1] == LAST_STEP, steps
    assert len(steps) == STEPS, steps
    # ... and the drawn geometry changed at nearly every one. Not at every one: on the sample the morph moves a
    # vertex by at most 5 tile units (0.6 px) over the whole level, so two neighbouring steps can round to the
    # same 1/16 px grid MapLibre draws on (over tile 11/545/800, the 32 steps give 29 distinct geometries).
    print(f"distinct shapes drawn over the level: {seen['shapes']} of {len(steps)} steps")
    assert seen["shapes"] >= MIN_SHAPES, seen


def test_wheel_zoom_through_a_level_fetches_each_morph_tile_once(app):
    app.page.set_viewport_size(SMALL)
    app.open()
    app.jump(center=CENTRE, zoom=11.0)
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.layers.main.state().plugin"), "CCSM is not drawn by the plugin"
    before = len(app.watch.tile_requests())
    install_probe(
        app.page,
        "window.ccsm.maps.a",
        "window.ccsm.layers.main.visibleLayerIds",
        "window.ccsm.layers.main.state().activeQ",
    )
    box = app.page.locator("#map-a").bounding_box()
    wheel_through_level(
        app.page,
        box["x"] + box["width"] / 2,
        box["y"] + box["height"] / 2,
        "() => window.ccsm.maps.a.getZoom()",
        "() => window.ccsm.layers.main.settled",
        until=LAST_STEP,
    )
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.maps.a.getZoom()") < 12
    assert_morphed_through_the_level(read_probe(app.page))

    # Not one tile request while the zoom stayed inside the level ...
    assert app.watch.tile_requests()[before:] == []
    # ... and every morph tile in view was fetched exactly once.
    morph = [u for u in app.watch.tile_requests() if "/morph/" in u]
    assert morph and all(c == 1 for c in Counter(morph).values()), Counter(morph).most_common(3)
    fetched = {(x, y) for z, x, y in map(tile_of, morph) if z == 11}
    assert visible_tiles(app.page, "window.ccsm.maps.a", 11) <= fetched


@pytest.fixture(scope="session")
def morph_archive(service_url: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A .pmtiles archive of the sample's morph tiles, zooms 10 to 12: written by `ccsm export` from the test
    service's store (a process of its own that is gone when the test runs), or, for a service given by
    CCSM_TEST_BASE_URL, fetched from it tile by tile (morph_pmtiles.py)."""
    out = tmp_path_factory.mktemp("archive") / "sample.pmtiles"
    dataset = next(d["id"] for d in httpx.get(f"{service_url}/datasets").json() if d.get("state") == "ready")
    store = SERVICE_STORES.get(service_url)
    if store is None:
        return morph_pmtiles_from_service(service_url, dataset, range(10, 13), out)
    export = ["export", dataset, "--store", str(store), "-o", str(out), "--minzoom", "10", "--maxzoom", "12"]
    subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *export], cwd=REPO, check=True, timeout=300
    )
    return out


@pytest.fixture(scope="session")
def maplibre_builds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[str, Path]]:
    """The oldest and the newest MapLibre of the plugin's peer range: (version, dist folder) of each."""
    releases = versions_in_range(peer_range())
    oldest, newest = releases[0], releases[-1]
    assert installed_version(PAGE_MAPLIBRE) == oldest, (
        f"the page pins MapLibre {installed_version(PAGE_MAPLIBRE)}; the plugin claims {peer_range()} from {oldest}"
    )
    newest_dist = install_maplibre(newest, tmp_path_factory.mktemp("maplibre")) if newest != oldest else None
    return {"oldest": (oldest, PAGE_MAPLIBRE / "dist"), "newest": (newest, newest_dist or PAGE_MAPLIBRE / "dist")}


@pytest.fixture(params=["oldest", "newest"])
def static_site(
    request: pytest.FixtureRequest, morph_archive: Path, maplibre_builds: dict[str, tuple[str, Path]]
) -> Iterator[Any]:
    """The plugin's example page, MapLibre (the oldest or the newest the plugin claims), the plugin and the
    archive on a static Range-capable server; ``server.maplibre_version`` says which MapLibre it serves."""
    version, dist = maplibre_builds[request.param]
    mounts = {
        "/vendor/maplibre-gl/": dist,
        "/web/": WEB,
        "/data/": morph_archive.parent,
    }
    with serve_static(mounts) as server:
        server.maplibre_version = version
        yield server


def test_static_pmtiles_without_the_service(browser, service_url, static_site, morph_archive):
    context = browser.new_context(viewport=SMALL)
    page, requests, errors = watched_page(context)
    try:
        with service_stopped(service_url):
            page.goto(f"{static_site.url}/web/plugin/example/index.html?url=pmtiles:///data/{morph_archive.name}")
            page.wait_for_function("() => window.contours && window.contours.settled", timeout=20_000)
            drawn_by = page.evaluate("() => import('maplibre-gl').then((m) => m.getVersion())")
            assert drawn_by == static_site.maplibre_version
            # The worker started under the page's import map (its modules import nothing by a bare name).
            assert page.evaluate("() => morph.rendererMode()") == "worker"
            page.evaluate("(c) => map.jumpTo({center: c, zoom: 11})", CENTRE)
            page.wait_for_function("() => contours.settled && contours.shownZoom === 11", timeout=20_000)
            ranges_before = len(static_site.requests_for(".pmtiles"))
            fetched_before = page.evaluate("() => morph.fetchCount")
            install_probe(page, "window.map", "window.contours.visibleLayerIds", "window.contours.shownZoom")
            wheel_through_level(
                page,
                SMALL["width"] / 2,
                SMALL["height"] / 2,
                "() => map.getZoom()",
                "() => contours.settled",
                LAST_STEP,
            )
            page.wait_for_function("() => contours.settled", timeout=20_000)
            seen = read_probe(page)
            fetched = page.evaluate("() => morph.fetchCount")
            visible = visible_tiles(page, "window.map", 11)
        assert errors == []
        # Only the static server was asked, and the archive was read with Range requests.
        assert all(u.startswith((static_site.url, "data:", "blob:")) for u in requests), requests
        archive = static_site.requests_for(".pmtiles")
        assert archive and all(rng and status == 206 for _, rng, status in archive), archive[:5]
        assert_morphed_through_the_level(seen)
        # Nothing read while the zoom stayed inside the level; each tile of the view was fetched once.
        assert len(static_site.requests_for(".pmtiles")) == ranges_before
        assert fetched == fetched_before >= len(visible)
    finally:
        context.close()
