"""The map `ccsm export -o FOLDER` writes, opened in Chromium from a plain Range-capable static server with the
tile service stopped: it draws what the service's own page draws at the same views (rank fading, index weight,
labels, hillshade; ink within 5 %, the same label texts) and asks for nothing while the zoom stays inside a
level, but the hillshade's raster tiles (MapLibre switches raster tiles at the half level, as on the service's
page).
"""

from __future__ import annotations

import base64
import io
import json
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import REPO, SERVICE_STORES, service_stopped, watched_page
from morph_probe import wheel_through_level
from PIL import Image
from static_server import RangeServer, serve_static

pytestmark = pytest.mark.browser

MINZOOM, MAXZOOM = 10, 12
#: (centre, zoom) of the compared views: most ranks faded at 10.4, the base interval fading in at 11.3, all
#: of it and the labels of every index contour at 12.6 (the sample's schedule).
VIEWS = [([-84.1113, 36.5273], 10.4), ([-84.1113, 36.5273], 11.3), ([-84.16, 36.56], 12.6)]
INK_TOLERANCE = 0.05
#: Zoom of the level the request count wheels through, and where the wheel stops (the last step short of 12).
LEVEL = 11
LAST_STEP = LEVEL + 31 / 32
#: The canvas pixels of the frame just drawn (MapLibre's drawing buffer is still whole in its `render` event).
CANVAS_PNG = """(expr) => new Promise((resolve) => {
    const m = eval(expr);
    m.once('render', () => resolve(m.getCanvas().toDataURL('image/png')));
    m.triggerRepaint();
})"""
#: The texts of the labels on screen, sorted.
LABEL_TEXTS = """([expr, ids]) =>
    eval(expr).queryRenderedFeatures({layers: ids}).map((f) => f.properties.label).sort()"""


@pytest.fixture(scope="module")
def exported_map(service_url: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder `ccsm export` writes from the test service's store (a process of its own, gone when the
    browser opens the folder)."""
    store = SERVICE_STORES.get(service_url)
    if store is None:
        pytest.skip("exporting needs the store of the service these tests start (not CCSM_TEST_BASE_URL)")
    dataset = next(d["id"] for d in httpx.get(f"{service_url}/datasets").json() if d.get("state") == "ready")
    out = tmp_path_factory.mktemp("export") / "map"
    args = ["export", dataset, "--store", str(store), "-o", str(out), "--minzoom", str(MINZOOM)]
    args += ["--maxzoom", str(MAXZOOM)]
    cmd = [sys.executable, "-c", "from app.cli import main; main()", *args]
    subprocess.run(cmd, cwd=REPO, check=True, timeout=600)
    return out


@pytest.fixture
def static_map(exported_map: Path) -> Iterator[RangeServer]:
    """The exported folder, as it is, on a static server that answers Range requests."""
    with serve_static({"/": exported_map}) as server:
        yield server


def canvas(page: Any, map_expr: str) -> np.ndarray:
    """The map's canvas as (h, w, 3) RGB floats."""
    url = page.evaluate(CANVAS_PNG, map_expr)
    png = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)


def ink(rgb: np.ndarray) -> dict[str, float]:
    """Two measures of what is drawn: ``contours``, the brown of lines and labels (red over blue, beyond the
    paper's and the hillshade's own), and ``all``, the darkness of everything (hillshade too)."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    brown = np.clip(r - b - 20.0, 0.0, None)
    darkness = 255.0 - (0.299 * r + 0.587 * g + 0.114 * b)
    return {"contours": float(brown.mean()), "all": float(darkness.mean())}


def service_views(app: Any, size: dict[str, int]) -> list[tuple[dict[str, float], list[str]]]:
    """Ink and label texts of the service's page at each view, its page chrome (the dataset's extent, the page's
    own paper) set to the style's so that only the drawn map differs."""
    page = app.page
    style = httpx.get(f"{app.base_url}/styles/{page.evaluate('() => window.ccsm.state.datasetId')}/style.json").json()
    paper = next(layer for layer in style["layers"] if layer["type"] == "background")["paint"]["background-color"]
    page.evaluate(
        """(paper) => {
            const m = window.ccsm.maps.a;
            for (const id of ['extent-fill', 'extent-line']) {
                if (m.getLayer(id)) m.setLayoutProperty(id, 'visibility', 'none');
            }
            m.setPaintProperty('background', 'background-color', paper);
        }""",
        paper,
    )
    labels = page.evaluate("() => window.ccsm.cartography.labelLayerIds")
    assert labels, "the service's page draws no label layer"
    out = []
    for centre, zoom in VIEWS:
        app.jump(center=centre, zoom=zoom)
        app.wait_settled()
        time.sleep(0.6)  # the labels' fade-in (300 ms)
        app.wait_settled()
        rgb = canvas(page, "window.ccsm.maps.a")
        assert rgb.shape[:2] == (size["height"], size["width"]), rgb.shape
        out.append((ink(rgb), page.evaluate(LABEL_TEXTS, ["window.ccsm.maps.a", labels])))
    return out


def wait_drawn(page: Any) -> None:
    """Until the exported page's morph shows the camera's step with all its tiles and MapLibre is idle."""
    page.wait_for_function("() => window.contours && contours.settled && map.loaded() && !map.isMoving()")
    time.sleep(0.6)
    page.wait_for_function("() => contours.settled && map.loaded()")


def test_exported_folder_draws_the_services_map_without_the_service(
    app: Any, browser: Any, service_url: str, static_map: RangeServer, exported_map: Path
) -> None:
    app.open()
    app.wait_settled()  # the status bar below the map takes its height once the dataset's legend is written
    size = app.page.evaluate("() => ({width: ccsm.maps.a.getCanvas().width, height: ccsm.maps.a.getCanvas().height})")
    assert app.page.evaluate("() => window.devicePixelRatio") == 1
    expected = service_views(app, size)

    style = json.loads((exported_map / "style.json").read_text())
    assert any(s.get("type") == "raster" for s in style["sources"].values()), "the sample has a DEM: hillshade"
    context = browser.new_context(viewport=size)
    context.set_default_timeout(30_000)
    page, requests, errors = watched_page(context, console_errors=True)
    try:
        with service_stopped(service_url):
            page.goto(f"{static_map.url}/index.html")
            wait_drawn(page)
            labels = page.evaluate("() => window.labelLayerIds")
            for (centre, zoom), (want_ink, want_labels) in zip(VIEWS, expected, strict=True):
                page.evaluate("([c, z]) => map.jumpTo({center: c, zoom: z})", [centre, zoom])
                wait_drawn(page)
                got_ink = ink(canvas(page, "window.map"))
                got_labels = page.evaluate(LABEL_TEXTS, ["window.map", labels])
                ratios = {k: got_ink[k] / want_ink[k] for k in want_ink}
                print(f"zoom {zoom}: ink export/service {ratios}; {len(got_labels)} labels")
                assert all(abs(r - 1) <= INK_TOLERANCE for r in ratios.values()), (zoom, got_ink, want_ink)
                assert got_labels == want_labels, (zoom, Counter(got_labels) - Counter(want_labels))
                assert want_labels or zoom < 11, f"no label at zoom {zoom}: nothing compared"

            # Inside a level: the contours and labels ask for nothing while the wheel zooms through it.
            page.evaluate("([c, z]) => map.jumpTo({center: c, zoom: z})", [VIEWS[0][0], LEVEL])
            wait_drawn(page)
            before = len(static_map.log)
            size_xy = (size["width"] / 2, size["height"] / 2)
            wheel_through_level(page, *size_xy, "() => map.getZoom()", "() => contours.settled", LAST_STEP)
            wait_drawn(page)
            assert LEVEL < page.evaluate("() => map.getZoom()") < LEVEL + 1
            inside = [path for path, _, _ in static_map.log[before:]]
        assert errors == []
        assert all(u.startswith((static_map.url, "data:", "blob:")) for u in requests), set(requests)
        archive = static_map.requests_for("contours.pmtiles")
        assert archive and all(rng and status == 206 for _, rng, status in archive), archive[:5]
        hillshade = [p for p in inside if "hillshade" in p]
        print(f"requests inside level {LEVEL}: {len(inside)} ({len(hillshade)} hillshade tiles at the half level)")
        assert [p for p in inside if p not in hillshade] == []
    finally:
        context.close()
