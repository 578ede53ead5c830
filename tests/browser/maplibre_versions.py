"""The MapLibre builds the plugin claims to work with (its peer range in web/plugin/package.json): the oldest is
the one the page pins (installed by ``npm ci`` in web/), the newest is asked of the npm registry and installed
into a scratch folder, so a new MapLibre release inside the range is tested the day it is published."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PLUGIN_MANIFEST = REPO / "web" / "plugin" / "package.json"
PAGE_MAPLIBRE = REPO / "web" / "node_modules" / "maplibre-gl"


def peer_range() -> str:
    """The plugin's peer range for maplibre-gl, e.g. ``^6.17.0``."""
    return str(json.loads(PLUGIN_MANIFEST.read_text())["peerDependencies"]["maplibre-gl"])


def installed_version(package_dir: Path) -> str:
    return str(json.loads((package_dir / "package.json").read_text())["version"])


def semver_key(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in version.split("-")[0].split("."))


def versions_in_range(spec: str) -> list[str]:
    """Every published maplibre-gl release inside ``spec``, oldest first (npm resolves the range)."""
    out = subprocess.run(
        ["npm", "view", f"maplibre-gl@{spec}", "version", "--json"],
        capture_output=True, text=True, timeout=120, check=True,
    ).stdout  # fmt: skip
    found = json.loads(out)
    return sorted([found] if isinstance(found, str) else found, key=semver_key)


def install_maplibre(version: str, into: Path) -> Path:
    """``maplibre-gl@version`` installed under ``into``; its dist folder (the files a page loads)."""
    into.mkdir(parents=True, exist_ok=True)
    subprocess.run(
        ["npm", "install", "--prefix", str(into), "--no-audit", "--no-fund", "--prefer-offline",
         "--loglevel=error", "--no-save", f"maplibre-gl@{version}"],
        capture_output=True, text=True, timeout=600, check=True,
    )  # fmt: skip
    package = into / "node_modules" / "maplibre-gl"
    assert installed_version(package) == version, installed_version(package)
    return package / "dist"
