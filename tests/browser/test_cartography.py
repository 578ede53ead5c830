"""The dataset's style.json in three clients, and no popping while zooming (issue 11; docs/clients.md).

1. MapLibre GL JS loads only the style URL (web/clients/maplibre.html) and draws contours, labels and the
   hillshade: rendered features of the style's layers, and pixels with and without those layers.
2. OpenLayers with ol-mapbox-style (web/clients/openlayers.html, both from web/node_modules) draws the same
   style: contour-coloured pixels, and more dark pixels with the label layers than without them.
3. No pop while wheel-zooming on the project's page, three zoom levels out and back in. Method: at every
   rendered frame the page records the contours and labels on screen (queryRenderedFeatures on the visible
   line layers and the label layers; a line by its feature id, a label by its text and anchor) with the zoom.
   Each one's opacity at that zoom follows from its own `fade_zoom` and `hide_zoom` (the style's ramp:
   exponential base 2 from 0 at hide_zoom to 1 at fade_zoom). Between consecutive frames, only inside the
   ground both frames show (so nothing counts for entering at the edge of the view), a line or label that is
   new in a frame must be drawn at most at FADE_EPS opacity there, and one that went must have been at most
   at FADE_EPS in the frame before: everything arrives and leaves by fading.
"""

from __future__ import annotations

import math

import httpx
import numpy as np
from PIL import Image

#: Opacity below which a line or label is "faint": appearing or going at or below it counts as fading.
FADE_EPS = 0.12
#: Pixels inside each frame's edge left out of the common ground (a line at the very edge may move across it).
EDGE_PX = 12

LIGHT_JS = """() => new Promise((resolve) => {
    const m = window.clientMap;
    const done = () => requestAnimationFrame(() => requestAnimationFrame(() => resolve(true)));
    if (m.loaded() && m.areTilesLoaded()) { done(); return; }
    m.once('idle', done);
})"""


def style_of(base_url: str, dataset: str = "sample") -> dict:
    return httpx.get(f"{base_url}/styles/{dataset}/style.json", timeout=30).json()


def centre_and_bounds(base_url: str) -> tuple[list[float], list[float]]:
    w, s, e, n = httpx.get(f"{base_url}/tiles/sample/tilejson.json", timeout=30).json()["bounds"]
    return [(w + e) / 2, (s + n) / 2], [w, s, e, n]


def luma(png: bytes) -> np.ndarray:
    import io

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
    return rgb @ np.array([0.299, 0.587, 0.114])


def open_client(app, page_name: str, query: str = "") -> None:
    app.page.goto(f"{app.base_url}/web/clients/{page_name}?dataset=sample{query}")


def test_maplibre_draws_contours_labels_and_hillshade_from_the_style(app):
    style = style_of(app.base_url)
    lines = [la["id"] for la in style["layers"] if la["type"] == "line"]
    labels = [la["id"] for la in style["layers"] if la["type"] == "symbol"]
    centre, _ = centre_and_bounds(app.base_url)
    open_client(app, "maplibre.html", f"#12/{centre[1]}/{centre[0]}")
    app.wait_until("() => window.clientMap && clientMap.loaded()", 60, what="the style loaded")
    app.page.evaluate(LIGHT_JS)
    drawn = app.page.evaluate(
        """([lines, labels]) => ({
            lines: clientMap.queryRenderedFeatures({layers: lines}).length,
            levels: [...new Set(clientMap.queryRenderedFeatures({layers: lines}).map((f) => f.properties.level))],
            labels: clientMap.queryRenderedFeatures({layers: labels}).map((f) => f.properties.label),
        })""",
        [lines, labels],
    )
    assert drawn["lines"] > 50, drawn
    assert sorted(drawn["levels"]) == [0, 1], "index and intermediate lines are both drawn"
    assert len(drawn["labels"]) >= 3 and all(t.endswith(" m") for t in drawn["labels"]), drawn["labels"]

    def frame(hidden: list[str]) -> np.ndarray:
        app.page.evaluate(
            "(ids) => clientMap.style._layers && clientMap.getStyle().layers.forEach((l) => "
            "clientMap.setLayoutProperty(l.id, 'visibility', ids.includes(l.id) ? 'none' : 'visible'))",
            hidden,
        )
        app.page.evaluate(LIGHT_JS)
        return luma(app.page.screenshot())

    everything = frame([])
    no_labels = frame(labels)
    no_ink = frame(labels + lines)
    no_hillshade = frame(labels + lines + ["hillshade"])
    # Labels, lines and relief each darken pixels of their own.
    assert ((no_labels - everything) > 40).sum() > 200, "labels drew no text"
    assert ((no_ink - no_labels) > 20).sum() > 2000, "no contour pixels"
    assert np.abs(no_hillshade - no_ink).mean() > 3, "no hillshade"
    assert app.watch.outside_requests == []


def test_openlayers_draws_contours_and_labels_from_the_same_style(app):
    style = style_of(app.base_url)
    centre, _ = centre_and_bounds(app.base_url)
    # OpenLayers zooms count 256 px tiles: one more than MapLibre's for the same scale.
    open_client(app, "openlayers.html", f"&lon={centre[0]}&lat={centre[1]}&zoom=13")
    app.wait_until("() => window.clientReady && window.clientMap", 60, what="ol-mapbox-style applied")
    app.page.evaluate("() => window.clientReady")

    def rendered() -> np.ndarray:
        app.page.evaluate(
            "() => new Promise((r) => { clientMap.once('rendercomplete', () => r(true)); clientMap.render(); })"
        )
        app.page.wait_for_timeout(300)
        return np.asarray(Image.open(__import__("io").BytesIO(app.page.screenshot())).convert("RGB"), dtype=int)

    full = rendered()
    # Contour ink: brown pixels (red well above blue) over the paper and the grey hillshade.
    brown = (full[..., 0] - full[..., 2] > 40).sum()
    assert brown > 2000, brown
    # The same style without its label layers, applied to a fresh map in the same place.
    no_labels = dict(style, layers=[la for la in style["layers"] if la["type"] != "symbol"])
    app.page.evaluate(
        """([s, lon, lat]) => {
            clientMap.setTarget(null);
            const view = new ol.View({center: ol.proj.fromLonLat([lon, lat]), zoom: 13});
            window.clientMap = new ol.Map({target: 'map', view});
            return olms.apply(clientMap, s).then(() => clientMap.setView(view));
        }""",
        [no_labels, *centre],
    )
    without = rendered()
    darker = (without.sum(axis=2) - full.sum(axis=2)) > 120
    assert darker.sum() > 200, "the label layers drew no text"
    assert app.watch.outside_requests == []


RECORD_JS = """(labelIds) => {
    const l = window.ccsm.layers.main, m = l.map;
    const frames = [];
    window.__frames = frames;
    const key = (f) => f.layer.type === 'symbol'
        ? `label:${f.properties.label}:${f.geometry.coordinates.map((v) => v.toFixed(5)).join(',')}`
        : `line:${f.id}`;
    m.on('render', () => {
        const zoom = m.getZoom();
        const b = m.getBounds();
        const seen = {};
        const layers = [...l.visibleLayerIds, ...labelIds.filter((id) => m.getLayer(id))];
        for (const f of m.queryRenderedFeatures({layers})) {
            const p = f.properties;
            const g = f.geometry;
            const pts = g.type === 'Point' ? [g.coordinates]
                : g.type === 'LineString' ? g.coordinates : g.coordinates.flat();
            const k = key(f);
            const entry = seen[k] ?? {fade: p.fade_zoom, hide: p.hide_zoom, pts: []};
            for (let i = 0; i < pts.length; i += Math.max(1, Math.floor(pts.length / 40))) entry.pts.push(pts[i]);
            seen[k] = entry;
        }
        frames.push({zoom, bounds: [b.getWest(), b.getSouth(), b.getEast(), b.getNorth()], seen});
    });
}"""


def opacity(entry: dict, zoom: float) -> float:
    """The style's ramp for one feature at a zoom (docs/clients.md)."""
    fade, hide = entry["fade"], entry["hide"]
    if hide is None or hide < 0 or zoom >= fade:
        return 1.0
    if zoom <= hide:
        return 0.0
    return (2 ** (zoom - hide) - 1) / (2 ** (fade - hide) - 1)


def inside(pts: list[list[float]], box: list[float]) -> bool:
    w, s, e, n = box
    return any(w <= x <= e and s <= y <= n for x, y in pts)


def common_ground(a: dict, b: dict) -> list[float]:
    """The ground both frames show, EDGE_PX inside each frame's edge (in degrees)."""

    def shrunk(f: dict) -> list[float]:
        w, s, e, n = f["bounds"]
        dx, dy = (e - w) * EDGE_PX / 1000, (n - s) * EDGE_PX / 700
        return [w + dx, s + dy, e - dx, n - dy]

    (w1, s1, e1, n1), (w2, s2, e2, n2) = shrunk(a), shrunk(b)
    return [max(w1, w2), max(s1, s2), min(e1, e2), min(n1, n2)]


def pops(frames: list[dict]) -> list[str]:
    """Lines and labels that appeared or went between two frames while drawn above FADE_EPS."""
    out = []
    for a, b in zip(frames, frames[1:], strict=False):
        box = common_ground(a, b)
        for k, entry in b["seen"].items():
            if k not in a["seen"] and inside(entry["pts"], box) and opacity(entry, b["zoom"]) > FADE_EPS:
                out.append(f"{k} appeared at zoom {b['zoom']:.3f} at opacity {opacity(entry, b['zoom']):.2f}")
        for k, entry in a["seen"].items():
            if k not in b["seen"] and inside(entry["pts"], box) and opacity(entry, a["zoom"]) > FADE_EPS:
                out.append(f"{k} went at zoom {b['zoom']:.3f} from opacity {opacity(entry, a['zoom']):.2f}")
    return out


def test_wheel_zoom_across_three_levels_shows_nothing_new_except_by_fading(app):
    app.page.set_viewport_size({"width": 1000, "height": 700})
    app.open()
    state = app.page.evaluate("() => window.ccsm.cartography")
    assert state["labelLayerIds"] and app.page.evaluate("() => window.ccsm.layers.main.state().plugin")
    centre, _ = centre_and_bounds(app.base_url)
    app.jump(center=centre, zoom=12.6)
    app.wait_settled()
    app.page.evaluate(RECORD_JS, state["labelLayerIds"])
    box = app.page.locator("#maps canvas").first.bounding_box()
    app.page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    for direction, until in ((1, 9.5), (-1, 12.5)):
        for _ in range(200):
            zoom = app.page.evaluate("() => window.ccsm.maps.a.getZoom()")
            if (zoom <= until) if direction > 0 else (zoom >= until):
                break
            app.page.mouse.wheel(0, 60 * direction)
            app.page.wait_for_timeout(80)
        app.wait_settled(60)
    frames = app.page.evaluate("() => window.__frames")
    zooms = [f["zoom"] for f in frames]
    assert min(zooms) <= 9.6 and max(zooms) >= 12.4 and len(frames) > 60, (min(zooms), max(zooms), len(frames))
    # The recording saw fading: lines at partial opacity, and a rank gone and back.
    partial = [
        opacity(e, f["zoom"]) for f in frames for e in f["seen"].values() if 0 < opacity(e, f["zoom"]) < 1
    ]
    assert len(partial) > 100, len(partial)
    problems = pops(frames)
    assert not problems, f"{len(problems)} pops, first: {problems[:8]}"
    assert not math.isnan(sum(zooms))
