"""Render a ccsm dataset in QGIS the way docs/clients.md tells a user to add it (run by Debian's /usr/bin/python3,
which sees python3-qgis; the project's venv does not).

    /usr/bin/python3 tests/browser/qgis_render.py BASE_URL DATASET LON LAT ZOOM OUT_DIR

A QgsVectorTileLayer from an XYZ template and a style URL, with its default style loaded (what QGIS's "Add"
does: it fetches the style URL and converts it), rendered headless (QT_QPA_PLATFORM=offscreen) to a 1000 x 700
image centred at (LON, LAT) at MapLibre zoom ZOOM, once as is (OUT_DIR/full.png) and once with the layer's
labels off (OUT_DIR/no_labels.png). Prints one JSON object: the converted style (renderer and labeling styles by
source layer) and every network problem QGIS logged. Nothing here knows the style's content.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from qgis.core import (  # noqa: E402  (QT_QPA_PLATFORM must be set before Qt loads)
    Qgis,
    QgsApplication,
    QgsCoordinateReferenceSystem,
    QgsDataSourceUri,
    QgsMapRendererSequentialJob,
    QgsMapSettings,
    QgsNetworkAccessManager,
    QgsNetworkReplyContent,
    QgsRectangle,
    QgsVectorTileLayer,
)
from qgis.PyQt.QtCore import QSize  # noqa: E402
from qgis.PyQt.QtGui import QColor  # noqa: E402
from qgis.PyQt.QtNetwork import QNetworkReply, QNetworkRequest  # noqa: E402

WIDTH, HEIGHT = 1000, 700
EARTH_RADIUS_M = 6378137.0
#: MapLibre zooms count 512 px tiles.
MAPLIBRE_TILE_PX = 512


def layer_uri(base_url: str, dataset: str) -> str:
    """The data source string of QGIS's "New Generic Connection" with the URL, zooms and style URL of
    docs/clients.md."""
    uri = QgsDataSourceUri()
    uri.setParam("type", "xyz")
    uri.setParam("url", f"{base_url}/tiles/{dataset}/{{z}}/{{x}}/{{y}}.mvt")
    uri.setParam("zmin", "0")
    uri.setParam("zmax", "16")
    uri.setParam("styleUrl", f"{base_url}/styles/{dataset}/style.json")
    return bytes(uri.encodedUri()).decode()


def extent_at(lon: float, lat: float, zoom: float) -> QgsRectangle:
    """EPSG:3857 extent of a WIDTH x HEIGHT view centred at (lon, lat) at MapLibre zoom ``zoom``."""
    x = math.radians(lon) * EARTH_RADIUS_M
    y = math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) * EARTH_RADIUS_M
    mpp = 2 * math.pi * EARTH_RADIUS_M / MAPLIBRE_TILE_PX / 2**zoom
    return QgsRectangle(x - WIDTH / 2 * mpp, y - HEIGHT / 2 * mpp, x + WIDTH / 2 * mpp, y + HEIGHT / 2 * mpp)


def render(layer: QgsVectorTileLayer, extent: QgsRectangle, out: Path) -> list[str]:
    """Render the layer alone over ``extent`` into ``out``; the renderer's errors."""
    settings = QgsMapSettings()
    settings.setLayers([layer])
    settings.setDestinationCrs(QgsCoordinateReferenceSystem("EPSG:3857"))
    settings.setOutputSize(QSize(WIDTH, HEIGHT))
    settings.setOutputDpi(96)
    settings.setBackgroundColor(QColor("white"))
    settings.setExtent(extent)
    job = QgsMapRendererSequentialJob(settings)
    job.start()
    job.waitForFinished()
    job.renderedImage().save(str(out))
    return [f"render error: {e.message}" for e in job.errors()]


def main(base_url: str, dataset: str, centre: tuple[float, float], zoom: float, out_dir: Path) -> dict:
    app = QgsApplication([], False)
    app.initQgis()
    problems: list[str] = []
    tiles: list[int] = []  # the HTTP status of every reply

    def logged(message: str, tag: str, level: Qgis.MessageLevel) -> None:
        if level in (Qgis.Warning, Qgis.Critical) and tag in ("Network", "Vector Tiles"):
            problems.append(f"{tag}: {message}")

    QgsApplication.messageLog().messageReceived.connect(logged)

    def finished(reply: QgsNetworkReplyContent) -> None:
        # Tile errors are not logged by QGIS 3.22's vector tile loader: every reply is checked here.
        url = reply.request().url().toString()
        status = reply.attribute(QNetworkRequest.HttpStatusCodeAttribute)
        tiles.append(status)
        if reply.error() != QNetworkReply.NoError or not status or status >= 400:
            problems.append(f"{url}: HTTP {status} ({reply.errorString()})")

    QgsNetworkAccessManager.instance().finished.connect(finished)
    QgsNetworkAccessManager.setTimeout(120_000)
    layer = QgsVectorTileLayer(layer_uri(base_url, dataset), "ccsm")
    error, loaded = layer.loadDefaultStyle()
    extent = extent_at(*centre, zoom)
    problems += render(layer, extent, out_dir / "full.png")
    labeling = layer.labeling().clone() if layer.labeling() else None
    layer.setLabeling(None)
    problems += render(layer, extent, out_dir / "no_labels.png")
    return {
        "qgis": Qgis.QGIS_VERSION,
        "valid": layer.isValid(),
        "style_loaded": loaded,
        "style_error": error,
        "line_styles": [s.layerName() for s in layer.renderer().styles() if s.isEnabled()],
        "label_styles": [s.layerName() for s in labeling.styles()] if labeling else [],
        "replies": len(tiles),
        "problems": problems,
    }


if __name__ == "__main__":
    base, name, lon, lat, z, out = sys.argv[1:7]
    print(json.dumps(main(base.rstrip("/"), name, (float(lon), float(lat)), float(z), Path(out))))
