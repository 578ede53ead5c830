"""The shaded relief of a dataset: found through the DEM path stored with it, shaded once per data version."""

from __future__ import annotations

import threading
from pathlib import Path

from engine.build.datasets import RELIEF_DEM_KEY
from engine.io.crs import crs_to_string
from engine.io.dem import read_dem
from engine.store.records import DatasetInfo
from engine.tiles.hillshade import ShadedRelief, shade_relief


def relief_dem_path(info: DatasetInfo) -> Path | None:
    """The DEM stored with a dataset for its hillshade, or None (none stored, or the file is gone)."""
    value = info.params.get(RELIEF_DEM_KEY)
    if not isinstance(value, str):
        return None
    path = Path(value)
    return path if path.is_file() else None


class ReliefCache:
    """Shaded reliefs by dataset, made on first use and kept while the dataset's data version holds."""

    def __init__(self) -> None:
        self._reliefs: dict[str, tuple[int, ShadedRelief | None]] = {}
        self._lock = threading.Lock()

    def relief(self, info: DatasetInfo) -> ShadedRelief | None:
        """The dataset's shaded relief, or None when it has no DEM.

        Raises
        ------
        SourceError
            The stored DEM can no longer be read.
        """
        with self._lock:
            cached = self._reliefs.get(info.id)
            if cached is not None and cached[0] == info.data_version:
                return cached[1]
            path = relief_dem_path(info)
            relief = None
            if path is not None:
                grid = read_dem(path)
                relief = shade_relief(grid.z, grid.transform, crs_to_string(grid.crs))
            self._reliefs[info.id] = (info.data_version, relief)
            return relief
