"""Node.js and the test-only packages (tests/app/node, ``npm ci`` there) the JS-reader tests run."""

from __future__ import annotations

import shutil
from pathlib import Path

#: The folder of the node scripts and their package.json.
NODE_DIR = Path(__file__).resolve().parents[1] / "app" / "node"


def node_available(package: str) -> bool:
    """True when ``node`` is on the path and ``package`` (e.g. "pmtiles", "@mapbox/vector-tile") is installed
    in :data:`NODE_DIR`."""
    return shutil.which("node") is not None and (NODE_DIR / "node_modules" / package).is_dir()
