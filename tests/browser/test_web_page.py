"""The page loads from the service alone, draws contours, and shows scale, t and hover information."""

from __future__ import annotations

import io
import re

import httpx
import numpy as np
import pytest
from PIL import Image

pytestmark = pytest.mark.browser


def contour_pixel_share(png: bytes) -> float:
    """Share of pixels in the brown of the main contours (background and extent fill are grey-beige)."""
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    brown = (rgb[..., 0] - rgb[..., 2] > 50) & (rgb[..., 1] < 170)
    return float(brown.mean())


def test_page_loads_and_draws_contours(app):
    app.open()
    # Screenshots read the composited page: no preserveDrawingBuffer needed.
    share = contour_pixel_share(app.page.locator("#map-a").screenshot())
    assert share > 0.005, f"only {share:.4%} of the map is contour-coloured"
    assert app.page.evaluate("() => window.ccsm.errors") == []


def test_everything_comes_from_the_service(app):
    app.open()
    requests = app.watch.requests
    assert any("/vendor/maplibre-gl/maplibre-gl.mjs" in u for u in requests)
    assert app.watch.outside_requests == []


def test_tile_urls_follow_the_tilejson_template(app):
    # CCSM comes from the morph tiles' TileJSON (the plugin, once per tile, no zoom= parameter); the baselines
    # from the per-level tiles' TileJSON with zoom= on the eighth grid and method=.
    app.open()
    dataset = app.page.evaluate("() => window.ccsm.state.datasetId")
    tilejson = httpx.get(f"{app.base_url}/tiles/{dataset}/tilejson.json").json()
    morph_tilejson = httpx.get(f"{app.base_url}/morph/{dataset}/tilejson.json").json()
    morph_prefix = httpx.URL(morph_tilejson["tiles"][0]).path.split("{z}")[0]
    # The labels come from the per-level tiles as the style's source names them (TileJSON template, no zoom=):
    # anchors are fixed, so they need no morph (docs/web.md).
    label_prefix = httpx.URL(tilejson["tiles"][0]).path.split("{z}")[0]
    requests = app.watch.tile_requests()
    labels = [u for u in requests if httpx.URL(u).path.startswith(label_prefix) and "zoom" not in httpx.URL(u).params]
    tiles = [u for u in requests if u not in labels]
    assert tiles and labels
    for url in tiles:
        assert httpx.URL(url).path.startswith(morph_prefix), url
        assert "zoom" not in httpx.URL(url).params, url
    assert len(tiles) == len(set(tiles)), "a morph tile was fetched twice"

    before = len(app.watch.tile_requests())
    app.page.select_option("#method", "dp")
    app.wait_settled()
    template_path = httpx.URL(tilejson["tiles"][0]).path
    prefix = template_path.split("{z}")[0]
    # Label tiles (the style's per-level source: neither zoom= nor method=) may follow the camera too.
    new = [u for u in app.watch.tile_requests()[before:] if set(httpx.URL(u).params) - {"v"}]
    assert new
    for url in new:
        u = httpx.URL(url)
        assert u.path.startswith(prefix), url
        z = int(re.search(r"/(\d+)/\d+/\d+\.mvt$", u.path).group(1))
        zoom = float(u.params["zoom"])
        assert z <= zoom < z + 1 and (zoom * 8).is_integer(), url
        assert u.params["method"] == "dp"


def test_readout_shows_scale_and_t(app):
    app.open()
    app.jump(zoom=11.5)
    app.wait_settled()
    app.wait_until("() => /t ≈ \\d/.test(document.getElementById('readout-t').textContent)", what="t readout")
    lat = app.page.evaluate("() => window.ccsm.maps.a.getCenter().lat")
    expected = 279_541_132.014 * np.cos(np.radians(lat)) / 2**11.5
    text = app.page.locator("#readout-scale").inner_text()
    shown = float(text.removeprefix("1:").replace(",", ""))
    assert shown == pytest.approx(expected, rel=0.01)
    assert "morph 11.500" in app.page.locator("#readout-zoom").inner_text()


def test_hover_shows_elevation_and_t(app):
    app.open()
    app.jump(zoom=11.5)
    app.wait_settled()
    # A contour vertex in the middle of the map with no other contour within 6 px, so that the tooltip (which
    # looks 4 px around the mouse) can only describe this contour.
    point = app.page.evaluate(
        """() => {
            const l = window.ccsm.layers.main, m = l.map;
            const c = m.getCanvas().getBoundingClientRect();
            const fs = m.queryRenderedFeatures(
                [[c.width * 0.3, c.height * 0.3], [c.width * 0.7, c.height * 0.7]], {layers: l.visibleLayerIds});
            for (const f of fs) {
                const lines = f.geometry.type === 'LineString' ? [f.geometry.coordinates] : f.geometry.coordinates;
                for (const [lng, lat] of lines.flat()) {
                    const p = m.project([lng, lat]);
                    if (!(p.x > c.width * 0.3 && p.x < c.width * 0.7 && p.y > c.height * 0.3 && p.y < c.height * 0.7))
                        continue;
                    const near = m.queryRenderedFeatures([[p.x - 6, p.y - 6], [p.x + 6, p.y + 6]],
                                                         {layers: l.visibleLayerIds});
                    const kinds = new Set(near.map(g => `${g.properties.elevation}|${g.properties.t}`));
                    if (near.length && kinds.size === 1)
                        return {x: c.left + p.x, y: c.top + p.y, elevation: near[0].properties.elevation,
                                t: near[0].properties.t, index: near[0].properties.index};
                }
            }
            return null;
        }"""
    )
    assert point, "no contour vertex standing alone in the middle of the map"
    app.page.mouse.move(point["x"] + 20, point["y"] + 20)
    app.page.mouse.move(point["x"], point["y"])
    app.wait_until("() => !document.getElementById('tooltip').hidden", what="tooltip")
    text = app.page.locator("#tooltip").inner_text()
    shown = re.search(r"(-?\d+(?:\.\d)?) m(?: \(index\))? · t = (\d\.\d{3})", text)
    assert shown, text
    assert float(shown.group(1)) == pytest.approx(point["elevation"], abs=0.05), (text, point)
    assert float(shown.group(2)) == pytest.approx(point["t"], abs=0.0005 + 1e-9), (text, point)  # 3 decimals
    assert ("(index)" in text) == bool(point["index"]), (text, point)
