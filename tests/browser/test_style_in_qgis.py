"""QGIS draws the dataset's contours and labels from the XYZ URL and the style URL alone (docs/clients.md, QGIS).

The real service on loopback (the browser tests' `service_url`), and Debian's QGIS 3.22 (`python3-qgis`, seen
by Debian's own /usr/bin/python3, not by the project's venv) run headless by tests/browser/qgis_render.py: a
vector tile layer made as docs/clients.md tells a user to make it, its style loaded from the style URL (QGIS
converts MapLibre styles itself), rendered at 1000 x 700 over the sample's centre with and without its labels.
Every HTTP reply QGIS got is checked, since QGIS leaves a tile it could not fetch blank without a word.
"""

from __future__ import annotations

import io
import json
import math
import os
import subprocess
import time
from pathlib import Path

import httpx
import numpy as np
from PIL import Image

QGIS_PYTHON = "/usr/bin/python3"
RENDER_SCRIPT = Path(__file__).with_name("qgis_render.py")
#: MapLibre zoom of the render: the sample's labels are all past their fade in there (first zooms reach 12.3).
ZOOM = 13.0
#: A pixel this much darker than the paper (luma) is ink.
INK_DARKER = 80.0
#: Pixels a dozen labels of about 75 px of text each darken (the sample's view holds about 30).
LABEL_PIXELS = 800
#: Label text is brown (red well above blue); QGIS 3.22 draws the lines grey (see docs/clients.md).
BROWN_RED_MINUS_BLUE = 40


def rgb(path: Path) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(path.read_bytes())).convert("RGB"), dtype=np.float64)


def luma(img: np.ndarray) -> np.ndarray:
    return img @ np.array([0.299, 0.587, 0.114])


def qgis_available() -> None:
    """Fail, never skip, when Debian's QGIS bindings are missing."""
    probe = subprocess.run([QGIS_PYTHON, "-c", "import qgis.core"], capture_output=True, text=True, timeout=120)
    assert probe.returncode == 0, (
        f"{QGIS_PYTHON} cannot import qgis.core: install Debian's QGIS bindings with "
        f"`sudo apt-get install --no-install-recommends python3-qgis`\n{probe.stderr[-800:]}"
    )


def wait_for_labels(base_url: str, centre: list[float], timeout_s: float = 240.0) -> None:
    """Ask for the tile under the centre until the service answers it (the first label tile places the
    dataset's labels, which takes seconds; meanwhile the service may answer 503 "try again")."""
    lon, lat = centre
    n = 2**13
    x = int((lon + 180) / 360 * n)
    y = int((1 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2 * n)
    deadline = time.monotonic() + timeout_s
    while True:
        status = httpx.get(f"{base_url}/tiles/sample/13/{x}/{y}.mvt", timeout=timeout_s).status_code
        if status == 200:
            return
        assert status == 503 and time.monotonic() < deadline, f"the centre tile answered {status}"
        time.sleep(5)


def test_qgis_draws_contours_and_labels_from_the_xyz_url_and_style_url(service_url, tmp_path):
    qgis_available()
    centre = httpx.get(f"{service_url}/tiles/sample/tilejson.json", timeout=30).json()["center"][:2]
    wait_for_labels(service_url, centre)
    # QGIS keeps HTTP replies (the style too) in a disk cache under XDG_CACHE_HOME: a fresh one per run, so
    # QGIS draws what the service serves now.
    xdg = {f"XDG_{k}": str(tmp_path / k.lower()) for k in ("CACHE_HOME", "CONFIG_HOME", "DATA_HOME", "RUNTIME_DIR")}
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", **xdg}
    run = subprocess.run(
        [QGIS_PYTHON, str(RENDER_SCRIPT), service_url, "sample", *map(str, centre), str(ZOOM), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["qgis"].startswith("3."), report
    assert report["style_loaded"], f"QGIS did not load the style URL: {report['style_error']}"
    assert report["problems"] == [], report["problems"][:10]
    # The style's line layers became renderer styles on the `contours` tile layer, its label layers labeling
    # styles on `contour_labels`.
    assert "contours" in report["line_styles"], report
    assert "contour_labels" in report["label_styles"], report

    full, no_labels = rgb(tmp_path / "full.png"), rgb(tmp_path / "no_labels.png")
    paper = float(np.median(luma(no_labels)))
    assert paper > 200, f"the paper is not light: luma {paper:.0f}"
    # Contours: many ink pixels without the labels (thin lines over most of the view at 1:36,000; 12 % measured).
    ink = luma(no_labels) < paper - INK_DARKER
    assert ink.mean() > 0.05, f"only {ink.mean():.3%} of the pixels are contour ink"
    # Labels: pixels the labels darken, and brown text pixels (the style's label colour) only they draw.
    darker = (luma(no_labels) - luma(full)) > INK_DARKER / 2
    assert darker.sum() > LABEL_PIXELS, f"the labels darkened only {darker.sum()} pixels"

    def brown(img: np.ndarray) -> np.ndarray:
        return (img[..., 0] - img[..., 2]) > BROWN_RED_MINUS_BLUE

    assert (brown(full) & ~brown(no_labels)).sum() > LABEL_PIXELS, "no brown label text"
