"""Make the README's pictures of the split view at three scales (docs/img/split-*.png): CCSM beside
Douglas–Peucker on the project's page, both through the dataset's style, 1000 x 560 px, saved with a 64-colour
palette (a fifth of the bytes; the page's flat colours lose nothing visible).

Run against a running service:  python tests/browser/capture_split_images.py http://127.0.0.1:8000 [OUT_DIR]
Not a test (pytest does not collect it); it reuses the browser settings of chromium_launch.py.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import httpx
from PIL import Image
from playwright.sync_api import sync_playwright

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from chromium_launch import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

from engine.tiles.scale import zoom_for_scale  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "img"
#: Scale denominator -> file name.
SCALES = {50_000: "split-50k.png", 250_000: "split-250k.png", 1_000_000: "split-1m.png"}
#: The picture at 1:50,000 shows the rugged middle of the sample (Pine Mountain), the others its centre.
DETAIL_CENTRE = (-84.25, 36.59)


def settle(page, timeout_s: float = 120) -> None:
    """Wait until the page says every layer shows what its camera asks for, three polls in a row."""
    deadline = time.monotonic() + timeout_s
    ok = 0
    while ok < 3:
        if time.monotonic() > deadline:
            raise TimeoutError(page.evaluate("() => window.ccsm.layerStates()"))
        ok = ok + 1 if page.evaluate("() => window.ccsm && window.ccsm.settled()") else 0
        time.sleep(0.2)
    page.wait_for_timeout(500)  # label fades (fadeDuration 300 ms) run out


def save_small(png: bytes, path: Path) -> None:
    """Write a screenshot as a 64-colour PNG."""
    import io

    image = Image.open(io.BytesIO(png)).convert("RGB")
    image.quantize(colors=64, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(path, optimize=True)


def main(base: str, out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    w, s, e, n = httpx.get(f"{base}/tiles/sample/tilejson.json", timeout=60).json()["bounds"]
    centre = ((w + e) / 2, (s + n) / 2)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1000, "height": 560})
        page.goto(f"{base}/?dataset=sample&view=split&compare=dp")
        page.wait_for_function("() => window.ccsm && window.ccsm.state.tilejson", timeout=120_000)
        settle(page)
        for scale, name in SCALES.items():
            lon, lat = DETAIL_CENTRE if scale == 50_000 else centre
            zoom = float(zoom_for_scale(scale, lat))
            page.evaluate("([c, z]) => window.ccsm.maps.a.jumpTo({center: c, zoom: z})", [[lon, lat], zoom])
            settle(page)
            png = page.screenshot(timeout=60_000)
            save_small(png, out / name)
            print(f"1:{scale:,} (zoom {zoom:.2f}) -> {out / name}")
        browser.close()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "http://127.0.0.1:8000", Path(sys.argv[2]) if len(sys.argv) > 2 else OUT)
