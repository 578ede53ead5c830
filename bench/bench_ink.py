"""Ink benchmark in Chromium on the bundled sample: prints numbers (it is not a test).

How dark the contours and labels make the map, at scales from the source scale 1:50,000 to the target scale
1:500,000 and on to 1:1,000,000, in Chromium at 1000 x 700 px. The map is the service's own style
(web/clients/maplibre.html loads GET /styles/sample/style.json) with the hillshade off.

Ink share, defined: each frame is taken twice, with the contour and label layers shown and hidden; a pixel's
ink is how much darker it is with them, (L_hidden - L_shown) / 255 with L the Rec. 601 luma, clipped at 0, so
a fully black pixel over white paper counts 1 and a half-transparent brown line counts less. The share is the
summed ink divided by the number of pixels over the data (the sample's extent on screen, a few pixels inside
its edge), so the empty map around a small dataset at small scales does not dilute it.

The issue's goal: from the source scale to the target scale the share stays within +-30 %, read strictly: of
its value at the source scale, so every scale from 1:50,000 to 1:500,000 must be within 0.7-1.3x the 1:50,000
share (printed per scale and as a verdict; max/min and the deviation from the mean are printed too). The old
all-levels look (every 20 m level at every scale, drawn as the page drew them before: 0.8 px lines, 1.8 px
index lines, no fade, no labels) is measured on the same frames for comparison, from the sample's GeoJSON.

Usage: python bench/bench_ink.py [--base-url URL]
       Without --base-url a tile service is started on loopback with a store in a temporary folder.
       Needs Debian's /usr/bin/chromium and `npm ci` in web/.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "browser"))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO))

from bench_morph import service  # noqa: E402
from chromium_launch import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

from engine.tiles.scale import zoom_for_scale  # noqa: E402

VIEWPORT = {"width": 1000, "height": 700}
SCALES = [50_000, 75_000, 100_000, 150_000, 250_000, 350_000, 500_000, 1_000_000]
SOURCE_SCALE, TARGET_SCALE = 50_000, 500_000
#: Pixels left out along the data's edge on screen (lines end there; the edge itself is not map ink).
EDGE_PX = 4
SAMPLE_GEOJSON = REPO / "data" / "sample" / "jacksboro_contours_20m.geojson"
#: The old look's layers, as the page drew every level before the style existed.
OLD_LAYERS = [
    {
        "id": "old-line",
        "type": "line",
        "source": "old",
        "filter": ["!=", ["%", ["get", "elevation"], 100], 0],
        "paint": {"line-color": "#8a4b1c", "line-width": 0.8},
    },
    {
        "id": "old-index",
        "type": "line",
        "source": "old",
        "filter": ["==", ["%", ["get", "elevation"], 100], 0],
        "paint": {"line-color": "#8a4b1c", "line-width": 1.8},
    },
]

SETTLE_JS = """() => new Promise((resolve) => {
    const m = window.clientMap;
    const done = () => requestAnimationFrame(() => requestAnimationFrame(() => resolve(true)));
    if (m.loaded() && m.areTilesLoaded()) { done(); return; }
    m.once('idle', done);
    m.triggerRepaint();
})"""


def luma(png: bytes) -> np.ndarray:
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
    return rgb @ np.array([0.299, 0.587, 0.114])


def set_visible(page: Any, ids: list[str], visible: bool) -> None:
    page.evaluate(
        "([ids, v]) => ids.forEach((id) => clientMap.setLayoutProperty(id, 'visibility', v ? 'visible' : 'none'))",
        [ids, visible],
    )


def ink_share(page: Any, ink_ids: list[str], bounds: list[float]) -> float:
    """Summed ink per data pixel of the current frame (see the module docstring)."""
    page.evaluate(SETTLE_JS)
    shown = luma(page.screenshot(timeout=120_000))
    set_visible(page, ink_ids, False)
    page.evaluate(SETTLE_JS)
    hidden = luma(page.screenshot(timeout=120_000))
    set_visible(page, ink_ids, True)
    x0, y0, x1, y1 = page.evaluate(
        """(b) => { const a = clientMap.project([b[0], b[3]]), c = clientMap.project([b[2], b[1]]);
                    return [a.x, a.y, c.x, c.y]; }""",
        bounds,
    )
    h, w = shown.shape
    c0, c1 = max(0, math.ceil(x0) + EDGE_PX), min(w, math.floor(x1) - EDGE_PX)
    r0, r1 = max(0, math.ceil(y0) + EDGE_PX), min(h, math.floor(y1) - EDGE_PX)
    ink = np.clip(hidden - shown, 0, None)[r0:r1, c0:c1] / 255.0
    return float(ink.mean())


def measure(browser: Any, url: str) -> tuple[list[float], list[float], float]:
    """The ink share at every scale with the service's style and with the old look; the latitude used."""
    style = httpx.get(f"{url}/styles/sample/style.json", timeout=60).json()
    bounds = httpx.get(f"{url}/tiles/sample/tilejson.json", timeout=60).json()["bounds"]
    ink_ids = [layer["id"] for layer in style["layers"] if layer["type"] in ("line", "symbol")]
    lon, lat = (bounds[0] + bounds[2]) / 2, (bounds[1] + bounds[3]) / 2
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    geojson = SAMPLE_GEOJSON.read_bytes()
    page.route("**/bench/old.geojson", lambda route: route.fulfill(body=geojson, content_type="application/json"))
    page.set_default_timeout(120_000)
    page.goto(f"{url}/web/clients/maplibre.html?dataset=sample")
    page.wait_for_function("() => window.clientMap && clientMap.loaded()", timeout=120_000)
    if any(layer["id"] == "hillshade" for layer in style["layers"]):
        set_visible(page, ["hillshade"], False)
    page.evaluate(
        """(layers) => { clientMap.addSource('old', {type: 'geojson', data: `${location.origin}/bench/old.geojson`});
                         for (const l of layers) clientMap.addLayer({...l, layout: {visibility: 'none'}}); }""",
        OLD_LAYERS,
    )
    old_ids = [layer["id"] for layer in OLD_LAYERS]
    new, old = [], []
    for scale in SCALES:
        zoom = float(zoom_for_scale(scale, lat))
        page.evaluate("([c, z]) => clientMap.jumpTo({center: c, zoom: z})", [[lon, lat], zoom])
        new.append(ink_share(page, ink_ids, bounds))
        set_visible(page, ink_ids, False)
        set_visible(page, old_ids, True)
        old.append(ink_share(page, old_ids, bounds))
        set_visible(page, old_ids, False)
        set_visible(page, ink_ids, True)
    context.close()
    return new, old, lat


#: The goal's band, relative to the share at the source scale.
GOAL_LO, GOAL_HI = 0.7, 1.3


def relative_to_source(values: list[float]) -> list[float]:
    """Each scale's share over the share at the source scale (SCALES[0])."""
    return [v / values[0] for v in values]


def spread(values: list[float]) -> tuple[float, float]:
    """max/min, and the largest deviation from the mean as a fraction of the mean."""
    mean = sum(values) / len(values)
    return max(values) / min(values), max(abs(v - mean) for v in values) / mean


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base-url", help="a running service (default: start one with a temporary store)")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    with service(args.base_url) as url, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            new, old, lat = measure(browser, url)
        finally:
            browser.close()
    print(f"Ink share over the sample's data, Chromium {VIEWPORT['width']}x{VIEWPORT['height']}, hillshade off")
    print(f"{'scale':>12} {'zoom':>6} {'style.json':>11} {'x source':>9} {'old look':>9} {'x source':>9}")
    rel_new, rel_old = relative_to_source(new), relative_to_source(old)
    for scale, a, ra, b, rb in zip(SCALES, new, rel_new, old, rel_old, strict=True):
        print(f"  1:{scale:>9,} {float(zoom_for_scale(scale, lat)):6.2f} {a:11.4f} {ra:9.2f} {b:9.4f} {rb:9.2f}")
    in_goal = [i for i, s in enumerate(SCALES) if SOURCE_SCALE <= s <= TARGET_SCALE]
    for name, values, rel in (("style.json", new, rel_new), ("old look", old, rel_old)):
        ratio, dev = spread([values[i] for i in in_goal])
        lo, hi = min(rel[i] for i in in_goal), max(rel[i] for i in in_goal)
        verdict = "within" if GOAL_LO <= lo and hi <= GOAL_HI else "OUTSIDE"
        print(
            f"{name}: 1:{SOURCE_SCALE:,}-1:{TARGET_SCALE:,} from {lo:.2f}x to {hi:.2f}x the source-scale share "
            f"({verdict} the goal {GOAL_LO}-{GOAL_HI}x); max/min {ratio:.2f}, largest deviation from the mean "
            f"{dev:+.0%}; at 1:1,000,000 {rel[-1]:.2f}x"
        )
    print(json.dumps({"scales": SCALES, "style": new, "old": old}))


if __name__ == "__main__":
    main()
