"""Method switch, split and overlay views, and the t pin."""

from __future__ import annotations

import httpx
import pytest
from browser_geometry import chamfer_px, frame_points

pytestmark = pytest.mark.browser

BIG_BOX = (-1e12, -1e12, 1e12, 1e12)


def test_method_switch(app):
    app.open()
    app.jump(zoom=10.5)
    app.wait_settled()
    ccsm = frame_points(app.rendered_lines(), BIG_BOX)
    for method in ["dp", "wm", "vw", "original"]:
        before = len(app.watch.tile_requests())
        app.page.select_option("#method", method)
        app.wait_settled()
        new = app.watch.tile_requests()[before:]
        assert new and all(httpx.URL(u).params["method"] == method for u in new), method
        assert app.page.evaluate("() => window.ccsm.layers.main.active.method") == method
        lines = frame_points(app.rendered_lines(), BIG_BOX)
        assert len(lines) > 0, f"{method}: nothing drawn"
        if method == "original":
            assert chamfer_px(ccsm, lines) > 0


def test_split_view_shows_ccsm_beside_the_other_method(app):
    app.open()
    app.page.select_option("#view", "split")
    app.page.select_option("#compare", "dp")
    app.wait_until("() => window.ccsm.layers.split && window.ccsm.layers.split.tilejson", what="split layer")
    app.wait_settled()
    assert app.page.locator("#map-b").is_visible()
    assert app.page.locator("#label-a").inner_text() == "CCSM"
    assert app.page.locator("#label-b").inner_text() == "Douglas–Peucker"
    assert app.page.evaluate("() => window.ccsm.layers.split.active.method") == "dp"
    assert app.rendered_lines("split")
    # Cameras are synced both ways.
    app.page.evaluate("() => window.ccsm.maps.b.jumpTo({zoom: 11.25})")
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.maps.a.getZoom()") == pytest.approx(11.25)
    assert app.page.evaluate("() => window.ccsm.layers.main.active.q") == 11.25


def test_overlay_view_draws_both_methods(app):
    app.open()
    app.page.select_option("#view", "overlay")
    app.page.select_option("#compare", "vw")
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.layers.overlay.active.method") == "vw"
    assert app.rendered_lines("main") and app.rendered_lines("overlay")
    app.page.select_option("#view", "single")
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.layers.overlay.active") is None


def test_t_slider_pins_t(app):
    app.open()
    before = len(app.watch.tile_requests())
    app.page.check("#t-pin")
    app.page.locator("#t-slider").fill("0.5")
    app.wait_settled()
    new = app.watch.tile_requests()[before:]
    assert any(httpx.URL(u).params.get("t") == "0.5" for u in new), new[:3]
    assert "t = 0.500 (pinned)" in app.page.locator("#readout-t").inner_text()
    ts = app.page.evaluate(
        """() => { const l = window.ccsm.layers.main;
                   return l.map.queryRenderedFeatures({layers: l.visibleLayerIds}).map(f => f.properties.t); }"""
    )
    assert ts and all(t == pytest.approx(0.5, abs=1e-3) for t in ts)
    app.page.uncheck("#t-pin")
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.layers.main.active.t") is None
