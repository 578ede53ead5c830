"""Without WebGL2 MapLibre throws "WebGL2 is required" and never fires idle: the page must say so plainly."""

from __future__ import annotations

import pytest
from chromium_launch import CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.browser


def test_without_webgl_the_page_explains(browser, service_url):
    no_webgl = [*CHROMIUM_ARGS, "--disable-webgl", "--disable-3d-apis"]
    b = browser.browser_type.launch(executable_path=CHROMIUM, args=no_webgl)
    try:
        page = b.new_page()
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{service_url}/")
        page.wait_for_function("() => window.ccsm && window.ccsm.failed", timeout=15_000)
        text = page.locator("#boot").inner_text()
        assert "WebGL2" in text, text
        assert errors == []
    finally:
        b.close()
