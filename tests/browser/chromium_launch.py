"""How the browser tests launch Debian's Chromium (shared by conftest.py and the scripts beside it).

A plain module with a unique name: importing ``conftest`` by name would get whichever conftest.py pytest loaded
last.
"""

from __future__ import annotations

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
