"""Make the README's pictures of the split view at three scales (docs/img/split-*.png): CCSM beside
Douglas–Peucker on the project's page, both through the dataset's style, 1000 x 560 px, saved with a 64-colour
palette (a fifth of the bytes; the page's flat colours lose nothing visible).

Run against a running service:  python tests/browser/capture_split_images.py http://127.0.0.1:8000 [OUT_DIR]
Not a test (pytest does not collect it); the places and the settling are those of the other capture scripts.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

from PIL import Image

sys.path.insert(0, str(Path(__file__).parent))
from capture_readme_images import settle  # noqa: E402
from capture_scale_images import OUT, sample_views  # noqa: E402  (puts the repository on the path too)
from chromium_launch import page_at  # noqa: E402

#: Scale denominator -> file name (1:50,000 at DETAIL_CENTRE, the others at the sample's centre).
SPLIT_IMAGES = {50_000: "split-50k.png", 250_000: "split-250k.png", 1_000_000: "split-1m.png"}
#: After the page settles: the label placement's own fade (300 ms) runs out.
LABEL_FADE_MS = 500


def save_small(png: bytes, path: Path) -> None:
    """Write a screenshot as a 64-colour PNG."""
    image = Image.open(io.BytesIO(png)).convert("RGB")
    image.quantize(colors=64, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(path, optimize=True)


def main(base: str, out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    url = f"{base}/?dataset=sample&view=split&compare=dp"
    with page_at(url, 1000, 560, "() => window.ccsm && window.ccsm.state.tilejson") as page:
        for scale, name, centre, zoom in sample_views(base, SPLIT_IMAGES):
            page.evaluate("([c, z]) => window.ccsm.maps.a.jumpTo({center: c, zoom: z})", [centre, zoom])
            settle(page, 120)
            page.wait_for_timeout(LABEL_FADE_MS)
            save_small(page.screenshot(timeout=60_000), out / name)
            print(f"1:{scale:,} (zoom {zoom:.2f}) -> {out / name}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "http://127.0.0.1:8000", Path(sys.argv[2]) if len(sys.argv) > 2 else OUT)
