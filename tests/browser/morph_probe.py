"""Watch a morph from inside the page: every rendered frame is checked for contours in a box in the middle of
the map (queryRenderedFeatures on the layers on screen), and every new step on screen is fingerprinted, so a
test can count the frames that drew no contour and the distinct shapes drawn. Also: a slow real mouse-wheel
zoom through a level.
"""

from __future__ import annotations

import time
from typing import Any

# Installs window.__probe on a map. `layers` is a JS expression giving the ids of the style layers on screen
# now (they change at every swap of the double buffer); `shown` one giving the zoom step on screen.
INSTALL = """([mapExpr, layersExpr, shownExpr]) => {
    const map = eval(mapExpr);
    const layers = () => eval(layersExpr);
    const shown = () => eval(shownExpr);
    const probe = {frames: 0, blank: 0, shapes: new Set(), steps: new Set(), last: undefined};
    probe.onRender = () => {
        const c = map.getCanvas().getBoundingClientRect(), x = c.width / 2, y = c.height / 2;
        const ids = layers();
        probe.frames += 1;
        // A blank frame: no contour in a box in the middle of the map (cheap enough for every frame).
        const box = [[x - 40, y - 40], [x + 40, y + 40]];
        if (!ids.length || !map.queryRenderedFeatures(box, {layers: ids}).length) { probe.blank += 1; return; }
        // Each new step on screen: fingerprint every contour drawn (all vertices, in the tile's own grid, which
        // is what MapLibre draws), so a step that moved no vertex counts as no new shape.
        const step = shown();
        if (step === probe.last) return;
        probe.last = step;
        probe.steps.add(step);
        let sx = 0, sy = 0, n = 0;
        for (const f of map.queryRenderedFeatures({layers: ids})) {
            const g = f.geometry;
            for (const line of g.type === 'LineString' ? [g.coordinates] : g.coordinates) {
                for (const [a, b] of line) { n += 1; sx += a * n; sy += b * n; }
            }
        }
        probe.shapes.add(`${n}:${sx.toFixed(9)}:${sy.toFixed(9)}`);
    };
    map.on('render', probe.onRender);
    window.__probe = probe;
}"""

READ = """() => ({frames: __probe.frames, blank: __probe.blank, shapes: __probe.shapes.size,
             steps: [...__probe.steps].filter((s) => s !== null).sort((a, b) => a - b)})"""


def install_probe(page: Any, map_expr: str, layers_expr: str, shown_expr: str) -> None:
    page.evaluate(INSTALL, [map_expr, layers_expr, shown_expr])


def read_probe(page: Any) -> dict[str, Any]:
    return page.evaluate(READ)


def wheel_through_level(
    page: Any,
    x: float,
    y: float,
    zoom_js: str,
    settled_js: str,
    until: float,
    delta: float = -3.9,
    timeout_s: float = 60.0,
) -> int:
    """Scroll the mouse wheel over (x, y) in small trackpad-like ticks until the map's zoom reaches ``until``,
    waiting after each tick until the morph shows the step the zoom asks for. With |delta| < 4 MapLibre zooms
    by log2(2 / (1 + exp(-|delta| / 100))) a tick: 0.028 for 3.9, less than one 1/32 step, so every step of
    the level is drawn. Returns the number of ticks."""
    page.mouse.move(x, y)
    deadline = time.monotonic() + timeout_s
    ticks = 0
    while page.evaluate(zoom_js) < until:
        if time.monotonic() > deadline:
            raise AssertionError(f"the wheel zoom did not reach {until} in {timeout_s} s (at {page.evaluate(zoom_js)})")
        page.mouse.wheel(0, delta)
        ticks += 1
        page.wait_for_function(settled_js, timeout=10_000)
    return ticks
