"""The dataset's style.json in three clients, and no popping while zooming (issue 11; docs/clients.md).

1. MapLibre GL JS loads only the style URL (web/clients/maplibre.html) and draws contours, labels and the
   hillshade: rendered features of the style's layers, and pixels with and without those layers.
2. OpenLayers with ol-mapbox-style (web/clients/openlayers.html, both from web/node_modules) draws the same
   style: contour-coloured pixels, and more dark pixels with the label layers than without them.
3. No pop while wheel-zooming on the project's page, three zoom levels out and back in, judged by what
   MapLibre draws. At every rendered frame the page records each contour and label on screen
   (queryRenderedFeatures on both morph buffers' line layers and the label layers, by feature id) with its drawn
   strength: the opacity its layer has in that frame, evaluated by MapLibre's own paint state (the style's
   expression at the frame's zoom with the feature's properties), times, for lines, the width relative to the
   width at `morph_fade` 1 (CCSM's own vanishing of small contours narrows them). Nothing here restates the
   style: a style whose fade is a step, or labels without their fade in, are drawn at full strength at once.
   Between consecutive frames, no line in the middle of the view (the middle 40 % box, whose ground the other
   frame shows as long as a frame zooms by less than a level, so nothing counts for entering at the view's
   edge) and no label anchored in the middle 80 % may change its strength by more than POP_JUMP: everything
   arrives and leaves by fading. A label is the same label in the other frame only where its anchor is within
   SAME_ANCHOR_PX on screen: a label placed anew per zoom is one label gone and another come. And a fade must
   be as wide as the style's: a label's strength (all style) follows the map's zoom, so between two frames
   showing it, it may change by at most FADE_SLOPE per zoom level the frames are apart; a fade cut to a fifth of
   its width is five times as steep. (A line's opacity is not judged so: the plugin cross-fades its buffers in
   time.)
"""

from __future__ import annotations

import math
import re
import time

import httpx
import numpy as np
from PIL import Image

#: The most a line's or label's drawn strength (opacity times relative width, as MapLibre evaluates them) may
#: change between two consecutive frames. A frame zooms by 0.1 or less (one wheel step is 40 / 450 of a level);
#: the steepest fades are a label's fade in (LABEL_FADE_IN_ZOOMS = 0.5: 0.2 per 0.1 of a zoom) and CCSM's own
#: vanishing of small contours (``morph_fade`` over half a level, drawn at the plugin's step; on this loaded
#: machine the plugin skips steps, and the largest jump seen was 0.29). A pop (no fade) is a jump of 1.
POP_JUMP = 0.5
#: The most a label's drawn strength may change per zoom level between two frames that both show
#: it (the frames' zoom apart, whatever it is). The style's steepest fades: a label's fade in
#: (LABEL_FADE_IN_ZOOMS = 0.5: 2 per level, drawn as a linear ramp between stops LABEL_RAMP_STEP apart) and a
#: rank's fade out, exponential base 2 over its span s, steepest at its top: ln 2 * 2^s / (2^s - 1), 1.39 per
#: level for a span of 1 and 2.37 for a span of 0.5 (a label's fade in under it adds to that).
#: Cut to a fifth of its width a fade is 5 times as steep (10 per level for a label's fade in, sampled as 4; 5.3
#: and 9.8 for rank spans of 1 and 0.5), so a bound of 3.5 per level lets the style's fades through and stops
#: a fifth-width one (checked without a browser below; not yet seen in a browser run on this loaded machine).
#: FADE_SLACK covers rounding in the style's stops.
FADE_SLOPE = 3.5
FADE_SLACK = 0.02
#: The middle box of the view whose lines are checked, as fractions of its width and height.
MIDDLE_LO, MIDDLE_HI = 0.3, 0.7
#: The box whose labels are checked. A label is a point: its anchor in this box of one frame is on screen in the
#: next as long as a frame zooms by less than log2(0.5 / 0.4) (the lines' box is smaller: a line is judged by
#: any of its pixels in the box, and its other pixels may lie anywhere).
LABEL_LO, LABEL_HI = 0.1, 0.9

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
    # Zoom 13: every label there is past its own fade in (first zooms of the sample reach 12.3).
    open_client(app, "maplibre.html", f"#13/{centre[1]}/{centre[0]}")
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
    assert len(drawn["labels"]) >= 1 and all(t.endswith(" m") for t in drawn["labels"]), drawn["labels"]

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
    assert ((no_labels - everything) > 40).sum() > 50, "labels drew no text"  # a few labels of thin text
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


RECORD_JS = """([labelIds, box, labelBox]) => {
    const l = window.ccsm.layers.main, m = l.map;
    const frames = [];
    window.__frames = frames;
    // How strongly MapLibre draws a rendered feature in this frame: its layer's opacity (and for lines the width
    // relative to the width at morph_fade 1), each evaluated by MapLibre's own paint state for this frame, i.e.
    // the style's expressions at the frame's zoom with the feature's properties. No copy of the style here.
    const strength = (f) => {
        const layer = m.getLayer(f.layer.id);
        const feature = {type: f.type === 'Point' ? 1 : 2, id: f.id, properties: f.properties};
        const value = (name, feat) => {
            const v = layer.paint.get(name);
            return typeof v?.evaluate === 'function' ? v.evaluate(feat, {}) : v;
        };
        if (layer.type === 'symbol') return value('text-opacity', feature);
        const full = value('line-width', {...feature, properties: {...f.properties, morph_fade: 1}});
        return value('line-opacity', feature) * (full > 0 ? Math.min(1, value('line-width', feature) / full) : 0);
    };
    // Both morph buffers and the label layers: a buffer being loaded is at opacity 0, so the strongest copy of
    // a line is the one on screen. A contour's several labels share its id: labels are told apart by place.
    const [[x0, y0], [x1, y1]] = labelBox;
    const inBox = (p) => p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1;
    m.on('render', () => {
        const lineIds = (l._plugin?.buffers ?? []).flatMap((b) => b.layerIds);
        const layers = [...lineIds, ...labelIds].filter((id) => m.getLayer(id));
        const lines = {}, opacity = {}, labels = [];
        for (const f of m.queryRenderedFeatures({layers})) {
            if (f.layer.type === 'symbol') {
                const [lng, lat] = f.geometry.coordinates;
                labels.push([f.id, lng, lat, strength(f), inBox(m.project([lng, lat]))]);
            } else {
                const drawn = strength(f);
                if (drawn >= (lines[f.id] ?? -1)) {
                    lines[f.id] = drawn;
                    const paint = m.getLayer(f.layer.id).paint.get('line-opacity');
                    const feature = {type: 2, id: f.id, properties: f.properties};
                    opacity[f.id] = typeof paint?.evaluate === 'function' ? paint.evaluate(feature, {}) : paint;
                }
            }
        }
        const middle = [...new Set(m.queryRenderedFeatures(box, {layers: lineIds.filter((id) => m.getLayer(id))})
            .map((f) => String(f.id)))];  // strings, as the keys of `lines` come back from JSON
        frames.push({zoom: m.getZoom(), lines, opacity, middle, labels});
    });
}"""

#: Two labels of the same contour in consecutive frames are the same label when their anchors are this close
#: on screen (pixels at the larger of the two frames' zooms). Anchors are fixed; each zoom's tiles round them to
#: their own grid (4096 per 512 px tile: 1/8 px at the tile's zoom, 1/4 px drawn a zoom further in), and a
#: contour's labels are hundreds of pixels apart. A label placed anew moves by more and counts as gone and come.
SAME_ANCHOR_PX = 2.0
#: MapLibre's tile size: 2^zoom of these span 360 degrees of longitude.
TILE_PX = 512


def anchor_gap_px(label: list, other: list, zoom: float) -> float:
    """How far apart on screen at ``zoom`` two labels' anchors (lng, lat at positions 1, 2) are, in pixels."""
    deg_per_px = 360.0 / (TILE_PX * 2.0**zoom)
    dlat_mercator = abs(other[2] - label[2]) / math.cos(math.radians(label[2]))  # Mercator stretches latitude
    return max(abs(other[1] - label[1]), dlat_mercator) / deg_per_px


def label_strength(label: list, others: list[list], zoom: float) -> float | None:
    """The strength of ``label`` (id, lng, lat, strength, in middle) in another frame's labels (None: not there)."""
    same = [o[3] for o in others if o[0] == label[0] and anchor_gap_px(label, o, zoom) < SAME_ANCHOR_PX]
    return max(same, default=None)


def too_steep(a: dict, b: dict) -> list[str]:
    """Labels anchored in the middle of both frames whose strength (all style) changed faster than
    FADE_SLOPE per zoom level between them: a fade narrower than the style's."""
    dz = abs(b["zoom"] - a["zoom"])
    bound = FADE_SLOPE * dz + FADE_SLACK
    out = []
    # Lines are not judged here: the plugin cross-fades its two morph buffers over time (their line-opacity
    # moves within a frame's zoom), so a line's opacity is not the style's alone.
    zoom = max(a["zoom"], b["zoom"])
    for label in (x for x in b["labels"] if x[4]):
        before = label_strength(label, a["labels"], zoom)
        if before is not None and abs(label[3] - before) > bound:
            change = f"{before:.2f} -> {label[3]:.2f}"
            out.append(f"label {label[0]} faded too fast at zoom {b['zoom']:.3f}: {change} in {dz:.3f} zoom")
    return out


def pops(frames: list[dict]) -> list[str]:
    """Lines and labels in the middle box of one frame whose drawn strength differs from the other frame's by more
    than POP_JUMP: came in (absent or faint before) or went (absent or faint after) in one frame; and those whose
    style faded faster than the style's fades do (:func:`too_steep`)."""
    out = []
    for a, b in zip(frames, frames[1:], strict=False):
        for k in b["middle"]:
            if b["lines"][k] - a["lines"].get(k, 0.0) > POP_JUMP:
                out.append(
                    f"line {k} came in at zoom {b['zoom']:.3f}: {a['lines'].get(k, 0.0):.2f} -> {b['lines'][k]:.2f}"
                )
        for k in a["middle"]:
            if a["lines"][k] - b["lines"].get(k, 0.0) > POP_JUMP:
                out.append(
                    f"line {k} went at zoom {b['zoom']:.3f}: {a['lines'][k]:.2f} -> {b['lines'].get(k, 0.0):.2f}"
                )
        zoom = max(a["zoom"], b["zoom"])
        for label in (x for x in b["labels"] if x[4]):
            if label[3] - (before := label_strength(label, a["labels"], zoom) or 0.0) > POP_JUMP:
                out.append(f"label {label[0]} came in at zoom {b['zoom']:.3f}: {before:.2f} -> {label[3]:.2f}")
        for label in (x for x in a["labels"] if x[4]):
            if label[3] - (after := label_strength(label, b["labels"], zoom) or 0.0) > POP_JUMP:
                out.append(f"label {label[0]} went at zoom {b['zoom']:.3f}: {label[3]:.2f} -> {after:.2f}")
        out += too_steep(a, b)
    return out


def record_wheel_zoom(app) -> list[dict]:
    """Wheel-zoom the project's page three levels out and back in over the sample, recording every frame."""
    app.open()
    state = app.page.evaluate("() => window.ccsm.cartography")
    assert state["labelLayerIds"] and app.page.evaluate("() => window.ccsm.layers.main.state().plugin")
    centre, _ = centre_and_bounds(app.base_url)
    app.jump(center=centre, zoom=12.6)
    app.wait_settled()
    canvas = app.page.locator("#maps canvas").first.bounding_box()
    w, h = canvas["width"], canvas["height"]
    middle = [[w * MIDDLE_LO, h * MIDDLE_LO], [w * MIDDLE_HI, h * MIDDLE_HI]]
    label_box = [[w * LABEL_LO, h * LABEL_LO], [w * LABEL_HI, h * LABEL_HI]]
    app.page.evaluate(RECORD_JS, [state["labelLayerIds"], middle, label_box])
    app.page.mouse.move(canvas["x"] + w / 2, canvas["y"] + h / 2)
    for direction, until in ((1, 9.6), (-1, 12.5)):
        for _ in range(200):
            zoom = app.page.evaluate("() => window.ccsm.maps.a.getZoom()")
            if (zoom <= until) if direction > 0 else (zoom >= until):
                break
            # Small wheel steps, given time: the plugin draws the steps it keeps up with, and recording every
            # frame slows the page (a step skipped under load is a jump of the geometry, not of the style).
            app.page.mouse.wheel(0, 40 * direction)
            app.page.wait_for_timeout(250)
        app.wait_settled(90)
    return app.page.evaluate("() => window.__frames")


#: The label layers' tiles (the dataset's own per-level tiles; the morph layer reads /morph/).
LABEL_TILES = re.compile(r"/tiles/sample/\d+/\d+/\d+\.mvt")


def test_the_page_is_not_settled_while_its_label_tiles_are_loading(app):
    # The pop test starts recording once the page says it is settled: a label tile still in flight then would
    # arrive as a label popping in before any zoom.
    app.open()
    centre, _ = centre_and_bounds(app.base_url)
    held = []

    def hold(route) -> None:
        held.append(route)

    app.page.route(LABEL_TILES, hold)
    app.jump(center=centre, zoom=13.3)  # label tiles of zoom 13, not fetched by the opening view
    morph_settled = """() => {
        const l = window.ccsm.layers.main, m = l.map;
        return l.settled && !m.isMoving() && m.isSourceLoaded(l.active.sourceId);
    }"""
    app.wait_until(morph_settled, 30, what="the contour lines settled")
    app.wait_until("() => true", 0)  # let the route handler take the label requests made so far
    assert held, "the view asked for no label tile"
    until = time.monotonic() + 1.0
    while time.monotonic() < until:
        assert not app.page.evaluate("() => window.ccsm.settled()"), "settled with its label tiles in flight"
        time.sleep(0.1)
    for route in held:
        route.continue_()
    app.page.unroute(LABEL_TILES)
    app.wait_settled()
    labels = app.page.evaluate(
        "(ids) => window.ccsm.maps.a.queryRenderedFeatures({layers: ids}).length",
        app.page.evaluate("() => window.ccsm.cartography").get("labelLayerIds"),
    )
    assert labels > 0, "no label drawn once the label tiles came"


def test_wheel_zoom_across_three_levels_shows_nothing_new_except_by_fading(app):
    frames = record_wheel_zoom(app)
    zooms = [f["zoom"] for f in frames]
    assert min(zooms) <= 9.7 and max(zooms) >= 12.4 and len(frames) > 20, (min(zooms), max(zooms), len(frames))
    # The middle box of one frame is on screen in the next as long as a frame zooms by less than log2(1 / 0.4).
    assert max(abs(a - b) for a, b in zip(zooms, zooms[1:], strict=False)) < 1.0
    problems = pops(frames)
    kinds = {kind: sum(kind in p for p in problems) for kind in ("came in", "went", "faded too fast")}
    assert not problems, f"{len(problems)} pops in {len(frames)} frames ({kinds}), first: {problems[:8]}"
    # No pop means something only if the recording saw fading: lines and labels drawn at partial strength on
    # the way (checked after the pops, so a style that pops is reported as popping).
    partial = {
        "line": sum(0.02 < v < 0.98 for f in frames for v in f["lines"].values()),
        "label": sum(0.02 < x[3] < 0.98 for f in frames for x in f["labels"]),
    }
    assert partial["line"] > 50 and partial["label"] > 5, partial


def test_a_fade_cut_to_a_fifth_of_its_width_is_a_pop() -> None:
    """The judge without a browser: frames a wheel step (40 / 450 of a level) apart through a rank's fade, as
    the style draws it (its own opacity function), pass; the same fade cut to a fifth of its width fails, though
    no single step of it jumps by POP_JUMP."""
    from engine.cartography.style import RankFade, rank_opacity_at

    def frames_through(fade: RankFade) -> list[dict]:
        zooms = np.arange(fade.fade_zoom + 0.3, (fade.hide_zoom or 0) - 0.3, -40 / 450)
        return [
            {"zoom": z, "lines": {"1": o}, "opacity": {"1": o}, "middle": ["1"], "labels": [["L", 0.0, 0.0, o, True]]}
            for z in zooms
            for o in [rank_opacity_at(fade, float(z))]
        ]

    style_fade = RankFade(0, 12.0, 11.0)
    assert pops(frames_through(style_fade)) == []
    cut = frames_through(RankFade(0, 12.0, 12.0 - 1.0 / 5))
    jumps = [abs(a["opacity"]["1"] - b["opacity"]["1"]) for a, b in zip(cut, cut[1:], strict=False)]
    assert max(jumps) < POP_JUMP  # the old judge, a jump of POP_JUMP alone, let it pass
    assert any("faded too fast" in p for p in pops(cut)), pops(cut)
