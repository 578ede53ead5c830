"""Morph benchmark in Chromium on the bundled sample: prints numbers (it is not a test).

1. Tile requests while zooming through one level (11.0 -> 11.97, the same eased camera path) on the project's
   page: CCSM with the ccsm-morph plugin, CCSM with the old eighth-swap (?morph=off), and the number of tiles
   in view (what a plain vector source would fetch).
2. Median frame time while morphing (requestAnimationFrame timestamps in the page, the same eased zoom through
   the level): the plugin against a plain MapLibre vector source of the same morph tiles (layer `contours`,
   drawn as at the level's start), alternating runs in one browser; the ratio (goal <= 1.2, issue 27).

Usage: python bench/bench_morph.py [--base-url URL] [--runs N]
       Without --base-url a tile service is started on loopback with a store in a temporary folder.
       Needs Debian's /usr/bin/chromium and `npm ci` in web/.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "browser"))

from chromium_launch import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

from tests.app.conftest import LiveServer  # noqa: E402

VIEWPORT = {"width": 640, "height": 480}
START, END, EASE_MS = 11.0, 11.97, 8000


@contextmanager
def service(base_url: str | None) -> Iterator[str]:
    if base_url:
        yield base_url.rstrip("/")
        return
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer({"CCSM_STORE_PATH": str(Path(tmp) / "store.ccsm.sqlite")}, log=Path(tmp) / "service.log")
        try:
            server.wait_healthy(300)
            server.wait_ready("sample", 300)  # a fresh store: the service builds the bundled sample first
            yield server.url
        finally:
            server.stop()


def tiles_in_view(page: Any, z: int) -> int:
    w, s, e, n = page.evaluate(
        "() => { const b = ccsm.maps.a.getBounds(); return [b.getWest(), b.getSouth(), b.getEast(), b.getNorth()]; }"
    )

    def tile(lon: float, lat: float) -> tuple[int, int]:
        r = math.radians(lat)
        return int((lon + 180) / 360 * 2**z), int((1 - math.log(math.tan(r) + 1 / math.cos(r)) / math.pi) / 2 * 2**z)

    (x0, y0), (x1, y1) = tile(w, n), tile(e, s)
    return (x1 - x0 + 1) * (y1 - y0 + 1)


def requests_through_level(browser: Any, url: str, centre: list[float], query: str) -> tuple[int, int, int]:
    """Tile requests on arriving at START, then while the page eases from START to END; the tiles in view."""
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    tiles: list[str] = []
    page.on("request", lambda r: tiles.append(r.url) if ".mvt" in r.url else None)
    page.goto(f"{url}/{query}")
    page.wait_for_function("() => window.ccsm && window.ccsm.state.tilejson && window.ccsm.settled()", timeout=120_000)
    arrive = len(tiles)
    page.evaluate("([c, z]) => ccsm.maps.a.jumpTo({center: c, zoom: z})", [centre, START])
    page.wait_for_function("() => ccsm.settled()", timeout=120_000)
    view = tiles_in_view(page, int(START))
    before = len(tiles)
    page.evaluate("([z, ms]) => ccsm.maps.a.easeTo({zoom: z, duration: ms, easing: (t) => t})", [END, EASE_MS])
    page.wait_for_timeout(200)
    page.wait_for_function("() => ccsm.settled()", timeout=120_000)
    context.close()
    return before - arrive, len(tiles) - before, view


FRAMES_JS = """async ([start, end, ms]) => {
    map.jumpTo({zoom: start});
    const ready = () => (window.contours ? window.contours.settled : true) && map.loaded();
    await new Promise((r) => { const f = () => (ready() ? r() : setTimeout(f, 50)); f(); });
    const ts = [];
    let on = true;
    const tick = (t) => { ts.push(t); if (on) requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
    const swaps0 = window.contours ? window.contours.swaps : 0;
    map.easeTo({zoom: end, duration: ms, easing: (t) => t});
    await new Promise((r) => map.once('moveend', r));
    on = false;
    const steps = window.contours ? window.contours.swaps - swaps0 : 0;
    const d = ts.slice(1).map((t, i) => t - ts[i]).sort((a, b) => a - b);
    return {frames: d.length, median: d[d.length >> 1], p90: d[Math.floor(d.length * 0.9)], steps};
}"""

PLAIN_JS = """([template, minzoom, maxzoom]) => {
    contours.remove();
    map.addSource('plain', {type: 'vector', tiles: [template], minzoom, maxzoom});
    map.addLayer({id: 'plain-lines', type: 'line', source: 'plain', 'source-layer': 'contours',
                  paint: {'line-color': '#8a4b1c', 'line-width': ['case', ['get', 'index'], 1.8, 0.8]}});
    window.contours = null;
}"""


def frame_times(
    browser: Any, url: str, centre: list[float], share: float | None, tilejson: dict[str, Any]
) -> dict[str, float]:
    """Frame times through the level: plain MapLibre (``share`` None) or the plugin with that ``loadShare``."""
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(f"{url}/web/plugin/example/index.html?url={tilejson['_url']}")
    page.wait_for_function("() => window.contours && window.contours.settled", timeout=120_000)
    page.evaluate("(c) => map.jumpTo({center: c})", centre)
    if share is not None:
        page.evaluate("(s) => { contours.loadShare = s; }", share)
    else:
        page.evaluate(PLAIN_JS, [tilejson["tiles"][0], tilejson.get("minzoom", 0), tilejson.get("maxzoom", 16)])
    page.wait_for_function("() => window.contours ? window.contours.settled : map.loaded()", timeout=120_000)
    # One warm-up pass (tiles of the level fetched and parsed), then the measured one.
    page.evaluate(FRAMES_JS, [START, END, EASE_MS])
    out = page.evaluate(FRAMES_JS, [START, END, EASE_MS])
    context.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base-url", help="a running ccsm service (default: start one)")
    ap.add_argument("--runs", type=int, default=3, help="alternating frame-time runs per variant")
    ap.add_argument(
        "--load-shares",
        default="0.333",
        help="comma-separated loadShare values of the plugin to time (its default 1/3; 1: steps back to back)",
    )
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with service(args.base_url) as url, sync_playwright() as pw:
        dataset = next(d["id"] for d in httpx.get(f"{url}/datasets").json() if d.get("state") == "ready")
        tj_url = f"/morph/{dataset}/tilejson.json"
        tilejson = {**httpx.get(f"{url}{tj_url}").json(), "_url": tj_url}
        w, s, e, n = tilejson["bounds"]
        centre = [(w + e) / 2, (s + n) / 2]
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        print(f"sample {dataset!r}, viewport {VIEWPORT['width']}x{VIEWPORT['height']}, zoom {START} -> {END}")

        p_arrive, plugin, view = requests_through_level(browser, url, centre, "?method=ccsm")
        e_arrive, eighth, _ = requests_through_level(browser, url, centre, "?method=ccsm&morph=off")
        print(f"1. tile requests: arriving at zoom {START}, then zooming through the level in {EASE_MS} ms")
        print(f"   tiles in view (a plain vector source fetches these once): {view}")
        print(f"   plugin (morph tiles, 32 steps per level):   {p_arrive:3d} + {plugin:3d}")
        print(f"   eighth-swap (per-level tiles, 8 per level): {e_arrive:3d} + {eighth:3d}")

        variants: dict[str, float | None] = {"plain": None}
        variants.update({f"plugin, loadShare {s}": float(s) for s in args.load_shares.split(",")})
        runs: dict[str, list[dict[str, float]]] = {name: [] for name in variants}
        for _ in range(args.runs):
            for name, share in variants.items():
                runs[name].append(frame_times(browser, url, centre, share, tilejson))
        med = {k: statistics.median(r["median"] for r in v) for k, v in runs.items()}
        print(f"2. frame time while zooming {START} -> {END} in {EASE_MS} ms (median of {args.runs} runs' medians)")
        for name, share in variants.items():
            frames = [int(r["frames"]) for r in runs[name]]
            p90 = statistics.median(r["p90"] for r in runs[name])
            drawn = [int(r["steps"]) for r in runs[name]]
            steps = "" if share is None else f", morph steps drawn per run {drawn} of 31"
            print(f"   {name:20s} {med[name]:7.1f} ms  (p90 {p90:.1f} ms, frames per run {frames}{steps})")
        for name, share in variants.items():
            if share is not None:
                print(f"   ratio {name} / plain: {med[name] / med['plain']:.2f}  (goal <= 1.2)")
        browser.close()


if __name__ == "__main__":
    main()
