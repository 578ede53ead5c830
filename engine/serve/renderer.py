"""Tiles from a store: the per-request work, none of which scales with the dataset.

A tile is: R*Tree lookup of the buffered tile -> the contours visible at the tile's scale and their t (each
from its own t(scale) table) -> the method's lines (:mod:`engine.serve.methods`) -> the chunks of those lines
that meet the tile, merged into runs of rows -> slice ``(1 - t) base + t top``, thin rows by significance,
quantise and drop repeats in one compiled pass -> clip the runs that cross the buffered tile's edge -> encode.

Every method goes through this one pipeline. :class:`Renderer` puts the pieces together, one job each: what is
known of each dataset version (:mod:`engine.serve.dataset_view`), the request checks
(:mod:`engine.serve.tile_request`), the cuts (:mod:`engine.serve.cutters`), the label layer
(:mod:`engine.serve.label_layer`) and morph tiles (:mod:`engine.serve.morph_tiles`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from engine.cartography.dataset import DatasetCartography
from engine.ccsm.regression import t_at_scales
from engine.checks import check_method
from engine.serve.cutters import TileCutter
from engine.serve.dataset_view import DatasetView
from engine.serve.feature_columns import T_DECIMALS, line_columns
from engine.serve.heads import DEFAULT_HEAD_CACHE_BYTES, DatasetHeads
from engine.serve.label_layer import LabelLayer
from engine.serve.methods import Method, TileContext, make_methods
from engine.serve.morph_tiles import MorphTiles
from engine.serve.pack import DatasetPack
from engine.serve.tile_request import TileOptions, TileResult, check_tile_request, scale_of_tile
from engine.store.records import ContourRecord, DatasetInfo, LabelAnchors
from engine.store.store import CCSStore
from engine.tiles.grid import Tile, buffered, tile_bounds
from engine.tiles.mvt import encode_line_tile

__all__ = ["Renderer", "TileOptions", "TileResult"]


class Renderer:
    """Renders tiles from a store, with in-memory caches.

    Parameters
    ----------
    store
        The store to read.
    options
        Tile grid and zoom range.
    contour_cache_bytes
        Memory for decoded contour rows and dataset packs.
    head_cache_bytes
        Memory for the contour heads of datasets too large to pack, all datasets together
        (:mod:`engine.serve.heads`); a dataset whose heads do not fit reads each tile's from the store.
    baseline_cache_entries
        Number of baseline results kept.
    baseline_max_vertices
        Largest contour each baseline method may simplify (e.g. ``{"wm": 50_000}``); none by default.
    """

    def __init__(
        self,
        store: CCSStore,
        options: TileOptions | None = None,
        *,
        contour_cache_bytes: int = 512 << 20,
        head_cache_bytes: int = DEFAULT_HEAD_CACHE_BYTES,
        baseline_cache_entries: int = 100_000,
        baseline_max_vertices: Mapping[str, int] | None = None,
    ) -> None:
        self.store = store
        self.options = options or TileOptions()
        self.methods: dict[str, Method] = make_methods(baseline_cache_entries, baseline_max_vertices)
        self.view = DatasetView(store, contour_cache_bytes, head_cache_bytes)
        self.label_layer = LabelLayer(self.view, self.options)
        self.cutter = TileCutter(self.options)
        self.morph = MorphTiles(self.view, self.label_layer, self.cutter, self.methods["ccsm"], self.options)

    # -- what is known of each dataset version (engine.serve.dataset_view) ---------------------------------
    def info(self, dataset: str) -> tuple[DatasetInfo, float | None]:
        """The dataset's metadata and contour interval (:meth:`DatasetView.info`)."""
        return self.view.info(dataset)

    def forget(self, dataset: str) -> None:
        """Drop everything cached of a dataset (after a delete or rebuild)."""
        self.view.forget(dataset)

    def cartography(self, dataset: str) -> DatasetCartography:
        """The dataset's cartography, made once per data version (:meth:`DatasetView.cartography`)."""
        return self.view.cartography(dataset)

    def pack(self, dataset: str) -> DatasetPack | None:
        """The dataset's contours packed, or None when it is too large (:meth:`DatasetView.pack`)."""
        return self.view.pack(dataset)

    def heads(self, dataset: str) -> DatasetHeads | None:
        """Every contour head of the dataset's version, or None (:meth:`DatasetView.heads`)."""
        return self.view.heads(dataset)

    def records(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decoded contour rows, in the order given (:meth:`DatasetView.records`)."""
        return self.view.records(fids)

    def labels(self, dataset: str) -> LabelAnchors:
        """The dataset's label anchors on index contours (:meth:`LabelLayer.labels`)."""
        return self.label_layer.labels(dataset)

    # -- tiles -------------------------------------------------------------------------------------------
    def method(self, name: str) -> Method:
        """The method of that name (raises InvalidParameter for an unknown one)."""
        return self.methods[check_method(name)]

    def scale_of_tile(self, tile: Tile, zoom: float) -> float:
        """Scale denominator a tile is drawn at: fractional ``zoom`` at the latitude of the tile's centre."""
        return scale_of_tile(tile, zoom)

    def check_tile_request(
        self, z: int, x: int, y: int, zoom: float | None, method: str, t: float | None
    ) -> tuple[Tile, float, float | None]:
        """Validate a tile request without rendering it (raises TileOutOfRange / InvalidParameter)."""
        return check_tile_request(self.options, z, x, y, zoom, method, t)

    def tile(
        self,
        dataset: str,
        z: int,
        x: int,
        y: int,
        *,
        zoom: float | None = None,
        method: str = "ccsm",
        t: float | None = None,
    ) -> TileResult:
        """Render one tile of a dataset.

        Parameters
        ----------
        dataset
            Stored dataset id.
        z, x, y
            XYZ tile index.
        zoom
            Fractional zoom in [z, z + 1) the tile is drawn at (default z).
        method
            ccsm, dp, wm, vw or original.
        t
            Pin t for every contour (method ccsm only; other methods ignore it).

        Returns
        -------
        TileResult
            ``data`` is None when no contour is visible in the tile.

        Raises
        ------
        TileOutOfRange, InvalidParameter, UnknownLayer
        """
        tile, zoomf, t_pin = self.check_tile_request(z, x, y, zoom, method, t)
        how = self.methods[method]
        info, _ = self.view.info(dataset)
        bounds = tile_bounds(tile)
        box = buffered(bounds, self.options.buffer_px, self.options.extent)
        scale = scale_of_tile(tile, zoomf)
        packed = self.view.packed(dataset, box, how.stored_rows)
        if packed is None:
            return TileResult(None, 0, zoomf, scale)
        pack, where = packed
        carto = self.view.cartography(dataset)
        idx = how.visible(pack, where, scale)
        idx = idx[carto.shown_in_tile(pack.elevation[idx], z)]
        if len(idx) == 0:
            return TileResult(None, 0, zoomf, scale)
        ts = self._ts(how, info, pack, idx, scale, t_pin)
        level_end = scale_of_tile(tile, float(z + 1))
        pinned = how.honours_t and t_pin is not None
        lines = how.tile_lines(pack, idx, ts, scale, TileContext(info, self.view, level_end, pinned))
        parts = self.cutter.cut(lines, bounds, box, snap=how.keeps_topology)
        if parts is None:
            return TileResult(None, 0, zoomf, scale)
        cs = idx[parts.owner]
        columns = line_columns(carto, pack.elevation[cs], [round(v, T_DECIMALS) for v in ts[parts.owner].tolist()])
        opts = self.options
        data = encode_line_tile(
            opts.layer, pack.fid[cs].tolist(), columns, parts.pts, parts.part_len, parts.part_count, opts.extent
        )
        return TileResult(data + self.label_layer.layer(dataset, tile), len(cs), zoomf, scale)

    @staticmethod
    def _ts(
        how: Method, info: DatasetInfo, pack: DatasetPack, idx: NDArray[np.intp], scale: float, t_pin: float | None
    ) -> NDArray[np.float64]:
        """Each drawn contour's t: the pinned one for a method that honours it, else its table's at ``scale``."""
        if how.honours_t and t_pin is not None:
            return np.full(len(idx), t_pin)
        return t_at_scales(info.ladder, pack.tables[idx], scale)

    def morph_tile(self, dataset: str, z: int, x: int, y: int) -> TileResult:
        """A morph tile (:meth:`MorphTiles.tile`; the format is in docs/morph-tiles.md).

        Raises
        ------
        TileOutOfRange, UnknownLayer
        """
        return self.morph.tile(dataset, z, x, y)
