"""The properties of contour features in tiles and morph tiles."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.cartography.dataset import DatasetCartography

#: Decimals of the ``t`` property (1e-4 of the source-to-target range is far below a pixel).
T_DECIMALS = 4


def line_columns(carto: DatasetCartography, elevations: NDArray[np.float64], ts: list[float]) -> dict[str, Any]:
    """The properties of contour features: elevation, index, t, then the cartography attributes (level, rank,
    fade_zoom, hide_zoom; docs/design.md section 9)."""
    cols = carto.line_columns(elevations)
    out: dict[str, Any] = {}
    for key in (carto.options.elevation_key, "index"):
        out[key] = cols.pop(key)
    out["t"] = ts
    out.update(cols)
    return out
