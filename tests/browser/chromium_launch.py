"""How the browser tests launch Debian's Chromium (shared by conftest.py and the scripts beside it).

A plain module with a unique name: importing ``conftest`` by name would get whichever conftest.py pytest loaded
last.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu-sandbox",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    # Without these Chromium keeps calling home on a machine with no outside network.
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@contextmanager
def page_at(url: str, width: int, height: int, ready_js: str, timeout_ms: float = 120_000) -> Iterator[Any]:
    """A Chromium page of ``width`` x ``height`` px at ``url``, once ``ready_js`` is true: how every capture
    script beside this one starts; the browser is closed when the block ends."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url)
            page.wait_for_function(ready_js, timeout=timeout_ms)
            yield page
        finally:
            browser.close()
