"""The ``contour_labels`` point layer of tiles and morph tiles (docs/design.md section 9.3): the label anchors of a
dataset version, with a grid over them, and the labels each tile holds."""

from __future__ import annotations

import threading

import numpy as np

from engine.build.labels import label_last_zoom, place_dataset_labels
from engine.cartography.dataset import label_columns
from engine.cartography.labels import LabelAnchors
from engine.serve.dataset_view import DatasetView
from engine.serve.point_grid import PointGrid
from engine.serve.tile_request import TileOptions
from engine.tiles.grid import Tile, tile_bounds
from engine.tiles.mvt import encode_point_tile

#: The point layer of contour labels in tiles and morph tiles (docs/design.md section 9.3).
LABEL_LAYER = "contour_labels"


class LabelLayer:
    """Label anchors per data version, and each tile's layer of them.

    Parameters
    ----------
    view
        The datasets the labels are of (their versions and cartography).
    options
        Tile grid and the served zoom range the labels are placed for.
    """

    def __init__(self, view: DatasetView, options: TileOptions) -> None:
        self.view = view
        self.options = options
        self._labels: dict[str, tuple[int, LabelAnchors, PointGrid]] = {}
        self._labels_lock = threading.Lock()  # placing a dataset's labels takes seconds: once, not per request
        view.also_forget(self.forget)

    def forget(self, dataset: str) -> None:
        """Drop the dataset's anchors (after a delete or rebuild)."""
        self._labels.pop(dataset, None)

    def labels(self, dataset: str) -> LabelAnchors:
        """The dataset's label anchors on index contours (docs/design.md section 9.3)."""
        return self.indexed_labels(dataset)[0]

    def indexed_labels(self, dataset: str) -> tuple[LabelAnchors, PointGrid]:
        """The dataset's label anchors and a grid over them: those the build stored with the data version, read
        once per version.

        A version stored without them, or placed for another served zoom range, has them placed here instead,
        once per data version (a minute or more for a large dataset).
        """
        info, _ = self.view.info(dataset)
        cached = self._labels.get(dataset)
        if cached is not None and cached[0] == info.data_version:
            return cached[1], cached[2]
        last_zoom = label_last_zoom(self.options.max_zoom)
        stored = self.view.store.labels(dataset)
        if stored is not None and stored.data_version == info.data_version and stored.last_zoom == last_zoom:
            anchors = stored.anchors
            grid = PointGrid.of(anchors.xy)
            self._labels[dataset] = (stored.data_version, anchors, grid)
            return anchors, grid
        with self._labels_lock:
            cached = self._labels.get(dataset)
            if cached is not None and cached[0] == info.data_version:
                return cached[1], cached[2]
            placed = place_dataset_labels(self.view.store, dataset, self.options.max_zoom)
            anchors = placed.anchors
            grid = PointGrid.of(anchors.xy)
            self._labels[dataset] = (placed.data_version, anchors, grid)
        return anchors, grid

    def layer(self, dataset: str, tile: Tile) -> bytes:
        """The ``contour_labels`` layer of a tile: labels shown somewhere in [z, z + 1) whose anchor lies in
        the tile (each label in exactly one tile per zoom); b"" when none."""
        labels, grid = self.indexed_labels(dataset)
        if len(labels) == 0:
            return b""
        b = tile_bounds(tile)
        extent = self.options.extent
        # Only the anchors near the tile are tested (one grid unit around it: rounding cannot reach further).
        mx, my = (b.maxx - b.minx) / extent, (b.maxy - b.miny) / extent
        near = grid.near(b.minx - mx, b.miny - my, b.maxx + mx, b.maxy + my)
        xy = labels.xy[near]
        gx = np.floor((xy[:, 0] - b.minx) / (b.maxx - b.minx) * extent).astype(np.int64)
        gy = np.floor((b.maxy - xy[:, 1]) / (b.maxy - b.miny) * extent).astype(np.int64)
        inside = (gx >= 0) & (gx < extent) & (gy >= 0) & (gy < extent) & (labels.min_zoom[near] < tile.z + 1)
        if not inside.any():
            return b""
        chosen = labels.select(near[inside])
        columns = label_columns(self.view.cartography(dataset), chosen)
        pts = np.column_stack([gx[inside], gy[inside]])
        return encode_point_tile(LABEL_LAYER, chosen.fid.tolist(), columns, pts, extent)
