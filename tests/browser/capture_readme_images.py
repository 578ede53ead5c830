"""Make the README's screenshot and morph animation (docs/img/web-*.png, docs/img/morph.gif).

Run against a running service:  python tests/browser/capture_readme_images.py http://127.0.0.1:8000
Not a test (pytest does not collect it); it opens its page as chromium_launch.py does.
"""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path

from PIL import Image

sys.path.insert(0, str(Path(__file__).parent))
from chromium_launch import page_at  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "img"


def settle(page, timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    ok = 0
    while ok < 3:
        if time.monotonic() > deadline:
            raise TimeoutError(page.evaluate("() => window.ccsm.layerStates()"))
        ok = ok + 1 if page.evaluate("() => window.ccsm && window.ccsm.settled()") else 0
        time.sleep(0.1)


def main(base: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    ready = "() => window.ccsm && window.ccsm.state.tilejson"
    with page_at(f"{base}/#map=10.6/36.585/-84.26", 1100, 700, ready, timeout_ms=60_000) as page:
        settle(page)
        page.screenshot(path=str(OUT / "web-map.png"))

        page.select_option("#view", "split")
        page.select_option("#compare", "dp")
        page.wait_for_function("() => window.ccsm.layers.split && window.ccsm.layers.split.tilejson")
        page.evaluate("() => window.ccsm.maps.a.jumpTo({zoom: 10.2, center: [-84.26, 36.585]})")
        settle(page)
        page.screenshot(path=str(OUT / "web-split.png"))
        page.select_option("#view", "single")

        # The morph: same camera, t pinned from 0 (source detail) to 1 (the 1:500,000 shape) and back.
        page.set_viewport_size({"width": 640, "height": 480})
        page.evaluate("() => window.ccsm.maps.a.jumpTo({zoom: 11.6, center: [-84.255, 36.59]})")
        page.check("#t-pin")
        frames = []
        ts = [i / 12 for i in range(13)]
        for t in ts:
            page.locator("#t-slider").fill(f"{t:.2f}")
            settle(page)
            png = page.locator("#map-a").screenshot()
            img = Image.open(io.BytesIO(png)).convert("RGB")
            img = img.resize((480, round(480 * img.height / img.width)))
            frames.append(img.quantize(colors=16))
        seq = frames + frames[-2:0:-1]
        seq[0].save(OUT / "morph.gif", save_all=True, append_images=seq[1:], duration=180, loop=0, optimize=True)
        w, h = frames[0].size
        strip = Image.new("RGB", (4 * w, h), "white")
        for i, k in enumerate([0, 4, 8, 12]):
            strip.paste(frames[k].convert("RGB"), (i * w, 0))
        strip.save(OUT / "morph-strip.png", optimize=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "http://127.0.0.1:8000")
