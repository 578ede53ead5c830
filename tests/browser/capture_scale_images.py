"""Make the README's pictures of the sample at three scales (docs/img/scale-*.png): the service's style.json in
MapLibre (web/clients/maplibre.html), hillshade on, 1000 x 700 px.

Run against a running service:  python tests/browser/capture_scale_images.py http://127.0.0.1:8000
Not a test (pytest does not collect it); it opens its page as chromium_launch.py does.
"""

from __future__ import annotations

import sys
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from chromium_launch import page_at  # noqa: E402

from engine.tiles.scale import zoom_for_scale  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "img"
#: Scale denominator -> file name.
SCALES = {50_000: "scale-50k.png", 250_000: "scale-250k.png", 1_000_000: "scale-1m.png"}
#: The picture at 1:50,000 shows the rugged middle of the sample (Pine Mountain), the others its centre.
DETAIL_CENTRE = (-84.25, 36.59)

SETTLE_JS = """() => new Promise((resolve) => {
    const m = window.clientMap;
    const done = () => setTimeout(() => requestAnimationFrame(() => resolve(true)), 400);
    if (m.loaded() && m.areTilesLoaded()) { done(); return; }
    m.once('idle', done);
})"""


def sample_views(base: str, names: dict[int, str]) -> list[tuple[int, str, list[float], float]]:
    """(scale, file name, centre, zoom) of each picture of the sample: 1:50,000 at DETAIL_CENTRE, the other
    scales at the centre of the sample's bounds."""
    w, s, e, n = httpx.get(f"{base}/tiles/sample/tilejson.json", timeout=60).json()["bounds"]
    views = []
    for scale, name in names.items():
        lon, lat = DETAIL_CENTRE if scale == 50_000 else ((w + e) / 2, (s + n) / 2)
        views.append((scale, name, [lon, lat], float(zoom_for_scale(scale, lat))))
    return views


def main(base: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    url = f"{base}/web/clients/maplibre.html?dataset=sample"
    with page_at(url, 1000, 700, "() => window.clientMap && clientMap.loaded()") as page:
        for scale, name, centre, zoom in sample_views(base, SCALES):
            page.evaluate("([c, z]) => clientMap.jumpTo({center: c, zoom: z})", [centre, zoom])
            page.evaluate(SETTLE_JS)
            page.screenshot(path=str(OUT / name), timeout=60_000)
            print(f"1:{scale:,} (zoom {zoom:.2f}) -> docs/img/{name}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "http://127.0.0.1:8000")
