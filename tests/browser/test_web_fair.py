"""A fair comparison (issue 27, item 3): every method drawn through the dataset's style in single, split and overlay
views (rank fades, index weight, labels, hillshade in both panes), a legend naming both methods, the attribution
in view, and a tooltip that follows the map."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from engine.tiles.scale import zoom_for_scale

pytestmark = pytest.mark.browser

#: The scale of the issue's report (the sample's 20 m lines are fading out there, rank by rank).
FADING_SCALE = 289_000
#: A method drawn through the same style fades its ranks as CCSM does: the mean drawn opacity of each rank's
#: lines in the two panes may differ by this much (the lines differ, the fade does not; without the style a
#: baseline draws every rank at 1 while CCSM's faded rank is at about 0.5).
RANK_OPACITY_GAP = 0.05
#: The panes' ink (dark pixels of the map canvas) may differ by this factor: both draw the same ranks at the same
#: strength; at full ink with no fading the baseline's pane had about twice CCSM's.
INK_RATIO = 1.25

#: queryRenderedFeatures of one layer set, with the opacity and width MapLibre draws each feature with in this
#: frame (its paint state evaluated for the feature at the map's zoom: the style's expressions, not a copy); the
#: width as it is once grown in (``morph_fade`` 1: CCSM narrows the small contours it lets vanish).
DRAWN_JS = """(name) => {
    const l = window.ccsm.layers[name], m = l.map;
    const value = (layer, prop, f, extra = {}) => {
        const v = layer.paint.get(prop);
        const feature = {type: 2, id: f.id, properties: {...f.properties, ...extra}};
        return typeof v?.evaluate === 'function' ? v.evaluate(feature, {}) : v;
    };
    return m.queryRenderedFeatures({layers: l.visibleLayerIds}).map((f) => {
        const layer = m.getLayer(f.layer.id);
        return {rank: f.properties.rank, level: f.properties.level, opacity: value(layer, 'line-opacity', f),
                width: value(layer, 'line-width', f, {morph_fade: 1}), color: String(f.layer.paint['line-color'])};
    });
}"""

#: A contour vertex in the middle of a layer set's map with nothing else within 6 px, in page pixels.
LONE_VERTEX_JS = """(name) => {
    const l = window.ccsm.layers[name], m = l.map;
    const c = m.getCanvas().getBoundingClientRect();
    const inMiddle = (p) => p.x > c.width * 0.3 && p.x < c.width * 0.7 && p.y > c.height * 0.3 && p.y < c.height * 0.7;
    const fs = m.queryRenderedFeatures([[c.width * 0.3, c.height * 0.3], [c.width * 0.7, c.height * 0.7]],
                                       {layers: l.visibleLayerIds});
    for (const f of fs) {
        const lines = f.geometry.type === 'LineString' ? [f.geometry.coordinates] : f.geometry.coordinates;
        for (const [lng, lat] of lines.flat()) {
            const p = m.project([lng, lat]);
            if (!inMiddle(p)) continue;
            const near = m.queryRenderedFeatures([[p.x - 6, p.y - 6], [p.x + 6, p.y + 6]], {layers: l.visibleLayerIds});
            if (near.length && new Set(near.map((g) => g.id)).size === 1) return {x: c.left + p.x, y: c.top + p.y};
        }
    }
    return null;
}"""


def fading_zoom(app) -> float:
    lat = app.page.evaluate("() => window.ccsm.maps.a.getCenter().lat")
    return float(zoom_for_scale(FADING_SCALE, lat))


def mean_opacity_by_rank(features: list[dict]) -> dict[int, float]:
    ranks: dict[int, list[float]] = {}
    for f in features:
        ranks.setdefault(int(f["rank"]), []).append(float(f["opacity"]))
    return {r: float(np.mean(v)) for r, v in ranks.items()}


def canvas_ink(app, selector: str) -> int:
    """Dark pixels (luma below 150: contour ink and label text, not paper or hillshade) of one map's canvas."""
    box = app.page.locator(f"{selector} canvas").bounding_box()
    png = app.page.screenshot(clip=box)
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
    return int(((rgb @ np.array([0.299, 0.587, 0.114])) < 150).sum())


def labels_drawn(app, name: str) -> list[str]:
    return app.page.evaluate(
        """(name) => { const m = window.ccsm.maps[name];
                       const ids = window.ccsm.cartographyOf(name).labelLayerIds;
                       return m.queryRenderedFeatures({layers: ids}).map((f) => f.properties.label); }""",
        name,
    )


def open_split(app, compare: str = "dp") -> None:
    app.open(f"?view=split&compare={compare}")
    app.wait_until("() => window.ccsm.layers.split && window.ccsm.layers.split.tilejson", what="split layer")
    app.jump(zoom=fading_zoom(app))
    app.wait_settled(60)
    app.page.wait_for_timeout(600)  # the label placement's own fade (300 ms) runs out


def test_split_view_draws_both_panes_through_the_same_style(app):
    open_split(app)
    ccsm, dp = app.page.evaluate(DRAWN_JS, "main"), app.page.evaluate(DRAWN_JS, "split")
    assert ccsm and dp
    by_rank = {"ccsm": mean_opacity_by_rank(ccsm), "dp": mean_opacity_by_rank(dp)}
    faded = [r for r, o in by_rank["ccsm"].items() if o < 0.9]
    assert faded, f"nothing fades at 1:{FADING_SCALE:,}, so this view tests nothing: {by_rank}"
    for rank, opacity in by_rank["ccsm"].items():
        assert by_rank["dp"].get(rank) == pytest.approx(opacity, abs=RANK_OPACITY_GAP), (rank, by_rank)
    # Index lines weighted as the style says, in both panes (heavier than the others of their pane).
    for features in (ccsm, dp):
        widths = {lv: max(f["width"] for f in features if f["level"] == lv) for lv in (0, 1)}
        assert widths[1] > widths[0], widths
    # Labels and hillshade in both panes.
    for name in ("a", "b"):
        assert labels_drawn(app, name), f"no label drawn on map {name}"
        assert app.page.evaluate("(n) => window.ccsm.cartographyOf(n).hillshadeLayerId", name), name
    legend = app.page.locator("#legend").inner_text()
    assert "CCSM" in legend and "Douglas–Peucker" in legend, legend
    ink_a, ink_b = canvas_ink(app, "#map-a"), canvas_ink(app, "#map-b")
    assert 1 / INK_RATIO < ink_b / ink_a < INK_RATIO, (ink_a, ink_b)


def test_every_map_attribution_is_in_view(app):
    open_split(app)
    bar = app.page.locator(".statusbar").bounding_box()
    for pane in ("#map-a", "#map-b"):
        attribution = app.page.locator(f"{pane} .maplibregl-ctrl-attrib").bounding_box()
        canvas = app.page.locator(f"{pane} canvas").bounding_box()
        assert attribution and attribution["height"] > 0, pane
        # Inside its own map and above the status bar (readout and legend), which overlaps no map.
        assert attribution["y"] + attribution["height"] <= min(bar["y"], canvas["y"] + canvas["height"]) + 0.5
        right = attribution["x"] + attribution["width"]
        assert canvas["x"] <= attribution["x"] and right <= canvas["x"] + canvas["width"], pane


def test_single_view_baseline_fades_its_ranks(app):
    app.open("?method=dp")
    app.jump(zoom=fading_zoom(app))
    app.wait_settled(60)
    drawn = mean_opacity_by_rank(app.page.evaluate(DRAWN_JS, "main"))
    assert any(o < 0.9 for o in drawn.values()), f"Douglas–Peucker drawn at full ink: {drawn}"
    assert labels_drawn(app, "a")


def test_overlay_draws_the_compared_method_thin_in_its_own_colour(app):
    app.open("?view=overlay&compare=dp")
    app.jump(zoom=fading_zoom(app))
    app.wait_settled(60)
    main, compared = app.page.evaluate(DRAWN_JS, "main"), app.page.evaluate(DRAWN_JS, "overlay")
    assert main and compared
    assert {f["color"] for f in main}.isdisjoint({f["color"] for f in compared})
    assert max(f["width"] for f in compared) < min(f["width"] for f in main)
    # The same fades as the main method's.
    ours, theirs = mean_opacity_by_rank(main), mean_opacity_by_rank(compared)
    for rank, opacity in ours.items():
        assert theirs.get(rank) == pytest.approx(opacity, abs=RANK_OPACITY_GAP), (rank, ours, theirs)
    legend = app.page.locator("#legend").inner_text()
    assert "CCSM" in legend and "Douglas–Peucker" in legend, legend


def hover_tooltip(app, layer: str = "main") -> str:
    point = app.page.evaluate(LONE_VERTEX_JS, layer)
    assert point, "no contour vertex standing alone in the middle of the map"
    app.page.mouse.move(point["x"] + 20, point["y"] + 20)
    app.page.mouse.move(point["x"], point["y"])
    app.wait_until("() => !document.getElementById('tooltip').hidden", what="tooltip")
    return app.page.locator("#tooltip").inner_text()


TOOLTIP_JS = "() => document.getElementById('tooltip').hidden ? null : document.getElementById('tooltip').textContent"


def test_tooltip_follows_the_method_and_goes_while_zooming(app):
    app.open()
    app.jump(zoom=11.5)
    app.wait_settled()
    assert hover_tooltip(app).endswith("· CCSM")
    # The method changed from the keyboard, the mouse resting on the map (no mouseout to hide the tooltip).
    app.page.evaluate(
        "() => { const s = document.getElementById('method'); s.value = 'dp'; s.dispatchEvent(new Event('change')); }"
    )
    shown = app.page.evaluate(TOOLTIP_JS)
    assert shown is None or shown.endswith("· Douglas–Peucker"), shown
    app.wait_settled()
    app.page.wait_for_timeout(300)
    shown = app.page.evaluate(TOOLTIP_JS)
    assert shown is None or shown.endswith("· Douglas–Peucker"), shown
    assert hover_tooltip(app).endswith("· Douglas–Peucker")
    # While the map zooms the tooltip goes (the contour under the mouse changes); read in the same task as the
    # zoom, before the map can be idle again.
    gone = app.page.evaluate(
        """() => { const m = window.ccsm.maps.a; m.jumpTo({zoom: m.getZoom() + 0.4});
                   return document.getElementById('tooltip').hidden; }"""
    )
    assert gone, "the tooltip stayed while the map zoomed"
