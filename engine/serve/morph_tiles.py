"""Morph tiles: the CCSM contours at zoom ``z`` and at ``z + 1`` with the same vertices, and their t at eight
steps through the level, so a client morphs between them (the format is in docs/morph-tiles.md); with snap
rounding on, the contours that would meet while morphing are held still (:mod:`engine.tiles.morph_untangle`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.regression import t_at_scales
from engine.serve.cutters import Runs, TileCutter, runs_meeting
from engine.serve.dataset_view import DatasetView
from engine.serve.feature_columns import T_DECIMALS, line_columns
from engine.serve.label_layer import LabelLayer
from engine.serve.methods import Method, TileContext, TileLines
from engine.serve.tile_request import TileOptions, TileResult, tile_latitude
from engine.tiles.grid import buffered, check_tile, tile_bounds
from engine.tiles.morph_crossings import MorphParts
from engine.tiles.morph_untangle import morph_weights, untangle
from engine.tiles.mvt import encode_line_tile
from engine.tiles.runs import RunSet, morph_runs
from engine.tiles.scale import scale_for_zoom, zoom_for_scale
from engine.types import Bounds

#: Samples of t through a zoom level in a morph tile (docs/morph-tiles.md: 8 keep the morph well within a
#: tile unit of the server's slices; 4 do not everywhere).
MORPH_T_SAMPLES = 8
#: Layers of a morph tile: the contours as at zoom z, and the same vertices as at zoom z + 1.
MORPH_START_LAYER = "contours"
MORPH_END_LAYER = "contours_end"


@dataclass(eq=False)
class MorphTiles:
    """Morph tiles of the datasets of ``view``, drawn by the continuous method ``ccsm``."""

    #: The datasets.
    view: DatasetView
    #: The label layer appended to each tile.
    labels: LabelLayer
    #: Cuts the level's end shapes when contours are held still.
    cutter: TileCutter
    #: The continuous method.
    ccsm: Method
    #: Tile grid and zoom range.
    options: TileOptions

    def tile(self, dataset: str, z: int, x: int, y: int) -> TileResult:
        """A morph tile: the CCSM contours at zoom ``z`` and at ``z + 1`` with the same vertices, and their t at
        eight steps through the level (the format is in docs/morph-tiles.md).

        Raises
        ------
        TileOutOfRange, UnknownLayer
        """
        tile = check_tile(z, x, y, self.options.min_zoom, self.options.max_zoom)
        info, _ = self.view.info(dataset)
        opts = self.options
        bounds = tile_bounds(tile)
        box = buffered(bounds, opts.buffer_px, opts.extent)
        lat = tile_latitude(tile)
        scales = scale_for_zoom(z + np.arange(MORPH_T_SAMPLES + 1) / MORPH_T_SAMPLES, lat)
        packed = self.view.packed(dataset, box, "ccs")
        if packed is None:
            return TileResult(None, 0, float(z), float(scales[0]))
        pack, where = packed
        carto = self.view.cartography(dataset)
        idx = where[scales[-1] < pack.vanish[where]]  # drawn somewhere in the level: at its finest end
        idx = idx[carto.shown_in_tile(pack.elevation[idx], z)]
        if len(idx) == 0:
            return TileResult(None, 0, float(z), float(scales[0]))
        ts = np.stack([t_at_scales(info.ladder, pack.tables[idx], float(s)) for s in scales])  # (9, n)
        ctx = TileContext(info, self.view, level_end_scale=float(scales[-1]))
        drawn = self.ccsm.tile_lines(pack, idx, ts[0], float(scales[0]), ctx)
        runs = runs_meeting(drawn, box)
        if runs is None:
            return TileResult(None, 0, float(z), float(scales[0]))
        a, b, run_owner = runs
        q0, q1, part_len, part_run = morph_runs(
            RunSet(a, b, drawn.column[run_owner], drawn.refill[run_owner]),
            ts[0][run_owner],
            ts[-1][run_owner],
            pack.ccs,
            self.cutter.min_significance(box),
            bounds,
            opts.extent,
            opts.buffer_px,
        )
        if len(part_len) == 0:
            return TileResult(None, 0, float(z), float(scales[0]))
        parts = MorphParts(q0, q1, part_len, run_owner[part_run])
        if opts.snap_rounding:
            parts = self.untangle(parts, drawn, (a, b, run_owner), ts, bounds)
            if len(parts.part_len) == 0:
                return TileResult(None, 0, float(z), float(scales[0]))
        q0, q1, part_len = parts.start, parts.end, parts.part_len
        owners, counts = np.unique(parts.part_owner, return_counts=True)
        cs = idx[owners]
        vanish = pack.vanish[cs]
        finite = np.isfinite(vanish)  # an infinite vanishing scale: a line that never goes
        appear = np.zeros(len(cs))
        appear[finite] = np.maximum(zoom_for_scale(vanish[finite], lat), 0.0)
        columns = line_columns(carto, pack.elevation[cs], np.round(ts[0][owners], T_DECIMALS).tolist())
        for k in range(1, MORPH_T_SAMPLES + 1):
            columns[f"t{k}"] = np.round(ts[k][owners], T_DECIMALS).tolist()
        columns["min_zoom"] = np.round(appear, T_DECIMALS).tolist()
        ids = pack.fid[cs].tolist()
        start = encode_line_tile(MORPH_START_LAYER, ids, columns, q0, part_len, counts, opts.extent)
        end = encode_line_tile(MORPH_END_LAYER, ids, {}, q1, part_len, counts, opts.extent)
        labels = self.labels.layer(dataset, tile)
        return TileResult(start + end + labels, len(cs), float(z), float(scales[0]))

    def untangle(
        self, parts: MorphParts, drawn: TileLines, runs: Runs, ts: NDArray[np.float64], bounds: Bounds
    ) -> MorphParts:
        """The morph tile's parts with the contours that would meet while a client morphs them held still
        (:mod:`engine.tiles.morph_untangle`), each at its snap-rounded shape at the level's end: every contour of
        the tile is shown there (a ring may not be yet at the start), so the exact shapes do not meet."""

        def snap() -> MorphParts:
            cut = self.cutter.cut_snapped(replace(drawn, slice_t=ts[-1]), runs, bounds)
            if cut is None:
                empty = np.zeros((0, 2), dtype=np.int64)
                return MorphParts(empty, empty, np.zeros(0, np.int64), np.zeros(0, np.int64))
            return MorphParts(cut.pts, cut.pts, cut.part_len, np.repeat(cut.owner, cut.part_count))

        w = morph_weights(np.round(ts, T_DECIMALS))  # the t a client reads: rounded as encoded
        return untangle(parts, w, snap)[0]
