"""Tiles from a store: the per-request work, none of which scales with the dataset.

A tile is: R*Tree lookup of the buffered tile -> the contours visible at the tile's scale and their t (each
from its own t(scale) table) -> the method's lines (:mod:`engine.serve.methods`) -> the chunks of those lines
that meet the tile, merged into runs of rows -> slice ``(1 - t) base + t top``, thin rows by significance,
quantise and drop repeats in one compiled pass -> clip the runs that cross the buffered tile's edge -> encode.

Every method goes through this one pipeline. A dataset that fits the contour memory is held as one
:class:`~engine.serve.pack.DatasetPack` (built once per data version); a larger one is packed per request
from the stretches of the touched contours' rows that meet the tile, read from their stored pieces
(:mod:`engine.serve.pieces`; the same tiles, about the same work).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.build.labels import DEFAULT_MAX_ZOOM, label_anchors, label_last_zoom, place_dataset_labels
from engine.cartography.dataset import DatasetCartography, dataset_cartography, label_columns
from engine.cartography.labels import LabelAnchors
from engine.ccsm.regression import t_at_scales
from engine.checks import check_method, check_t
from engine.intervals import infer_interval
from engine.serve.cache import LRUCache
from engine.serve.heads import DEFAULT_HEAD_CACHE_BYTES, DatasetHeads, head_bytes
from engine.serve.methods import Method, TileContext, TileLines, make_methods
from engine.serve.pack import PACK_BYTES_PER_VERTEX, DatasetPack
from engine.serve.pieces import pack_of_pieces
from engine.serve.point_grid import PointGrid
from engine.store.sqlite import CCSStore, ContourRecord, DatasetInfo
from engine.tiles.clip import clip_lines_exact, clip_lines_fast
from engine.tiles.crossings import lines_cross_in_grid
from engine.tiles.grid import Tile, buffered, check_fractional_zoom, check_tile, tile_bounds, tile_center_latitude
from engine.tiles.morph_untangle import MorphParts, morph_weights, untangle
from engine.tiles.mvt import encode_line_tile, encode_point_tile
from engine.tiles.runs import morph_runs, ranges, slice_runs, slice_runs_exact
from engine.tiles.scale import scale_for_zoom, zoom_for_scale
from engine.tiles.snap_round import snap_round
from engine.types import Bounds

#: Decimals of the ``t`` property (1e-4 of the source-to-target range is far below a pixel).
T_DECIMALS = 4
#: Samples of t through a zoom level in a morph tile (docs/morph-tiles.md: 8 keep the morph well within a
#: tile unit of the server's slices; 4 do not everywhere).
MORPH_T_SAMPLES = 8
#: Layers of a morph tile: the contours as at zoom z, and the same vertices as at zoom z + 1.
MORPH_START_LAYER = "contours"
MORPH_END_LAYER = "contours_end"
#: The point layer of contour labels in tiles and morph tiles (docs/design.md section 9.3).
LABEL_LAYER = "contour_labels"


@dataclass(frozen=True)
class TileOptions:
    """How tiles are cut: grid size, buffer (grid units), layer name, served zoom range, and whether tiles
    where plain rounding makes lines cross are snap-rounded (always, but for tests that show what it guards)."""

    extent: int = 4096
    buffer_px: int = 64
    layer: str = "contours"
    min_zoom: int = 0
    max_zoom: int = DEFAULT_MAX_ZOOM
    snap_rounding: bool = True


@dataclass(frozen=True)
class TileResult:
    """A rendered tile: MVT bytes (None when it has no feature), the zoom and scale it was drawn at."""

    data: bytes | None
    features: int
    zoom: float
    scale: float


@dataclass(frozen=True)
class TileParts:
    """The quantised, clipped lines of a tile, feature by feature (before encoding).

    ``pts`` holds every part of every feature concatenated; ``part_len`` the points of each part and
    ``part_count`` the parts of each feature; ``owner`` is each feature's position in the contours drawn.
    """

    pts: NDArray[np.int64]
    part_len: NDArray[np.int64]
    part_count: NDArray[np.int64]
    owner: NDArray[np.int64]


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
        self.contours: LRUCache[int, ContourRecord] = LRUCache(contour_cache_bytes, lambda r: r.nbytes + 1024)
        self.contour_cache_bytes = contour_cache_bytes
        self.head_cache_bytes = head_cache_bytes
        self._heads: dict[str, DatasetHeads] = {}
        self._info: dict[str, tuple[DatasetInfo, float | None]] = {}
        self._packs: dict[str, DatasetPack] = {}
        self._cartography: dict[str, tuple[int, DatasetCartography]] = {}
        self._labels: dict[str, tuple[int, LabelAnchors, PointGrid]] = {}
        self._labels_lock = threading.Lock()  # placing a dataset's labels takes seconds: once, not per request
        self._pack_lock = threading.Lock()

    # -- datasets ----------------------------------------------------------------------------------------
    def info(self, dataset: str) -> tuple[DatasetInfo, float | None]:
        """The dataset's metadata and contour interval (stored, else inferred), cached per data_version.

        Raises
        ------
        UnknownLayer
            The dataset is not stored.
        """
        version = self.store.data_version(dataset)
        cached = self._info.get(dataset)
        if cached is not None and version is not None and cached[0].data_version == version:
            return cached
        info = self.store.dataset(dataset)
        interval = info.interval or infer_interval(self.store.elevations(dataset))
        self._info[dataset] = (info, interval)
        return info, interval

    def forget(self, dataset: str) -> None:
        """Drop cached metadata of a dataset (after a delete or rebuild; contour rows get new fids anyway)."""
        self._info.pop(dataset, None)
        self._packs.pop(dataset, None)
        self._heads.pop(dataset, None)
        self._cartography.pop(dataset, None)
        self._labels.pop(dataset, None)

    def cartography(self, dataset: str) -> DatasetCartography:
        """The dataset's options, interval schedule and label anchors, made once per data version
        (docs/design.md section 9)."""
        info, interval = self.info(dataset)
        cached = self._cartography.get(dataset)
        if cached is not None and cached[0] == info.data_version:
            return cached[1]
        carto = dataset_cartography(info, interval, self.store.elevations(dataset))
        self._cartography[dataset] = (info.data_version, carto)
        return carto

    def pack(self, dataset: str) -> DatasetPack | None:
        """The dataset's contours packed (built once per data version), or None when the dataset is larger
        than the contour memory."""
        info, interval = self.info(dataset)
        pack = self._packs.get(dataset)
        if pack is not None and pack.data_version == info.data_version:
            return pack
        if info.n_vertices * PACK_BYTES_PER_VERTEX > self.contour_cache_bytes:
            return None
        with self._pack_lock:
            pack = self._packs.get(dataset)
            if pack is None or pack.data_version != info.data_version:
                recs = self.store.load(self.store.all_fids(dataset))
                pack = DatasetPack.of(info.data_version, recs, interval)
                self._packs[dataset] = pack
        return pack

    def heads(self, dataset: str) -> DatasetHeads | None:
        """Every contour head of the dataset's version (read once per data version), or None when they do not
        fit in the head memory beside the other datasets' heads held."""
        info, _ = self.info(dataset)
        held = self._heads.get(dataset)
        if held is not None and held.data_version == info.data_version:
            return held
        with self._pack_lock:
            held = self._heads.pop(dataset, None)
            if held is not None and held.data_version == info.data_version:
                self._heads[dataset] = held  # read by another thread meanwhile
                return held
            others = sum(h.heads.nbytes for h in self._heads.values())
            if others + head_bytes(info.n_contours, len(info.ladder)) > self.head_cache_bytes:
                return None
            held = DatasetHeads.read(self.store, dataset, info.data_version)
            self._heads[dataset] = held
        return held

    def records(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decoded contour rows, from the cache or the store, in the order given (unknown fids skipped)."""
        out: list[ContourRecord | None] = [self.contours.get(f) for f in fids]
        missing = [f for f, r in zip(fids, out, strict=True) if r is None]
        if missing:
            loaded = {r.fid: r for r in self.store.load(missing)}
            for f, r in loaded.items():
                self.contours.put(f, r)
            out = [r if r is not None else loaded.get(f) for f, r in zip(fids, out, strict=True)]
        return [r for r in out if r is not None]

    def packed(self, dataset: str, box: Bounds, rows: str | None) -> tuple[DatasetPack, NDArray[np.intp]] | None:
        """The contours a tile's buffered ``box`` meets, in a pack, and their positions in it; None when there
        is none.

        The pack is the dataset's, or one of just the pieces of the contours' ``rows`` (``ccs``, ``original``, or
        None for the baselines, which draw from whole decoded contours) that meet ``box``
        (:mod:`engine.serve.pieces`).
        """
        pack = self.pack(dataset)
        if pack is not None:
            fids = self.store.query(dataset, box)
            if not fids:
                return None
            where = pack.locate(fids)
            if where is None:  # the store changed under the pack: take the new version
                self.forget(dataset)
                pack = self.pack(dataset)
                where = pack.locate(fids) if pack is not None else None
            if pack is not None and where is not None:
                return pack, where
        info, interval = self.info(dataset)
        part = pack_of_pieces(self.store, dataset, box, info.data_version, interval, rows, self.heads(dataset))
        return None if part is None or len(part.fid) == 0 else (part, np.arange(len(part.fid)))

    def labels(self, dataset: str) -> LabelAnchors:
        """The dataset's label anchors on index contours (docs/design.md section 9.3)."""
        return self.indexed_labels(dataset)[0]

    def indexed_labels(self, dataset: str) -> tuple[LabelAnchors, PointGrid]:
        """The dataset's label anchors and a grid over them: those the build stored with the data version, read
        once per version.

        A version stored without them, or placed for another served zoom range, has them placed here instead,
        once per data version (a minute or more for a large dataset).
        """
        info, _ = self.info(dataset)
        cached = self._labels.get(dataset)
        if cached is not None and cached[0] == info.data_version:
            return cached[1], cached[2]
        last_zoom = label_last_zoom(self.options.max_zoom)
        stored = self.store.labels(dataset)
        if stored is not None and stored.data_version == info.data_version and stored.last_zoom == last_zoom:
            anchors = label_anchors(stored)
            grid = PointGrid.of(anchors.xy)
            self._labels[dataset] = (stored.data_version, anchors, grid)
            return anchors, grid
        with self._labels_lock:
            cached = self._labels.get(dataset)
            if cached is not None and cached[0] == info.data_version:
                return cached[1], cached[2]
            placed = place_dataset_labels(self.store, dataset, self.options.max_zoom)
            anchors = label_anchors(placed)
            grid = PointGrid.of(anchors.xy)
            self._labels[dataset] = (placed.data_version, anchors, grid)
        return anchors, grid

    def label_layer(self, dataset: str, tile: Tile) -> bytes:
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
        columns = label_columns(self.cartography(dataset), chosen)
        pts = np.column_stack([gx[inside], gy[inside]])
        return encode_point_tile(LABEL_LAYER, chosen.fid.tolist(), columns, pts, extent)

    # -- tiles -------------------------------------------------------------------------------------------
    def method(self, name: str) -> Method:
        """The method of that name (raises InvalidParameter for an unknown one)."""
        return self.methods[check_method(name)]

    def scale_of_tile(self, tile: Tile, zoom: float) -> float:
        """Scale denominator a tile is drawn at: fractional ``zoom`` at the latitude of the tile's centre."""
        lat = max(-85.05, min(85.05, tile_center_latitude(tile)))
        return float(scale_for_zoom(zoom, lat))

    def check_tile_request(
        self, z: int, x: int, y: int, zoom: float | None, method: str, t: float | None
    ) -> tuple[Tile, float, float | None]:
        """Validate a tile request without rendering it (raises TileOutOfRange / InvalidParameter)."""
        tile = check_tile(z, x, y, self.options.min_zoom, self.options.max_zoom)
        zoomf = check_fractional_zoom(z, zoom)
        check_method(method)
        return tile, zoomf, check_t(t)

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
        info, _ = self.info(dataset)
        bounds = tile_bounds(tile)
        box = buffered(bounds, self.options.buffer_px, self.options.extent)
        scale = self.scale_of_tile(tile, zoomf)
        packed = self.packed(dataset, box, how.stored_rows)
        if packed is None:
            return TileResult(None, 0, zoomf, scale)
        pack, where = packed
        carto = self.cartography(dataset)
        idx = how.visible(pack, where, scale)
        idx = idx[carto.shown_in_tile(pack.elevation[idx], z)]
        if len(idx) == 0:
            return TileResult(None, 0, zoomf, scale)
        if how.honours_t and t_pin is not None:
            ts = np.full(len(idx), t_pin)
        else:
            ts = t_at_scales(info.ladder, pack.tables[idx], scale)
        level_end = self.scale_of_tile(tile, float(z + 1))
        pinned = how.honours_t and t_pin is not None
        lines = how.tile_lines(pack, idx, ts, scale, TileContext(info, self, level_end, pinned))
        parts = self.cut(lines, bounds, box, snap=how.keeps_topology)
        if parts is None:
            return TileResult(None, 0, zoomf, scale)
        cs = idx[parts.owner]
        columns = line_columns(carto, pack.elevation[cs], [round(v, T_DECIMALS) for v in ts[parts.owner].tolist()])
        opts = self.options
        data = encode_line_tile(
            opts.layer, pack.fid[cs].tolist(), columns, parts.pts, parts.part_len, parts.part_count, opts.extent
        )
        return TileResult(data + self.label_layer(dataset, tile), len(cs), zoomf, scale)

    def morph_tile(self, dataset: str, z: int, x: int, y: int) -> TileResult:
        """A morph tile: the CCSM contours at zoom ``z`` and at ``z + 1`` with the same vertices, and their t at
        eight steps through the level (the format is in docs/morph-tiles.md).

        Raises
        ------
        TileOutOfRange, UnknownLayer
        """
        tile = check_tile(z, x, y, self.options.min_zoom, self.options.max_zoom)
        info, _ = self.info(dataset)
        opts = self.options
        bounds = tile_bounds(tile)
        box = buffered(bounds, opts.buffer_px, opts.extent)
        lat = max(-85.05, min(85.05, tile_center_latitude(tile)))
        scales = scale_for_zoom(z + np.arange(MORPH_T_SAMPLES + 1) / MORPH_T_SAMPLES, lat)
        packed = self.packed(dataset, box, "ccs")
        if packed is None:
            return TileResult(None, 0, float(z), float(scales[0]))
        pack, where = packed
        carto = self.cartography(dataset)
        idx = where[scales[-1] < pack.vanish[where]]  # drawn somewhere in the level: at its finest end
        idx = idx[carto.shown_in_tile(pack.elevation[idx], z)]
        if len(idx) == 0:
            return TileResult(None, 0, float(z), float(scales[0]))
        ts = np.stack([t_at_scales(info.ladder, pack.tables[idx], float(s)) for s in scales])  # (9, n)
        ctx = TileContext(info, self, level_end_scale=float(scales[-1]))
        drawn = self.methods["ccsm"].tile_lines(pack, idx, ts[0], float(scales[0]), ctx)
        runs = runs_meeting(drawn, box)
        if runs is None:
            return TileResult(None, 0, float(z), float(scales[0]))
        a, b, run_owner = runs
        q0, q1, part_len, part_run = morph_runs(
            a,
            b,
            ts[0][run_owner],
            ts[-1][run_owner],
            drawn.column[run_owner],
            drawn.refill[run_owner],
            pack.ccs.sig,
            pack.ccs.base,
            pack.ccs.top,
            self.min_significance(box),
            bounds,
            opts.extent,
            opts.buffer_px,
        )
        if len(part_len) == 0:
            return TileResult(None, 0, float(z), float(scales[0]))
        parts = MorphParts(q0, q1, part_len, run_owner[part_run])
        if opts.snap_rounding:
            parts = self.untangle_morph(parts, drawn, (a, b, run_owner), ts, bounds)
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
        labels = self.label_layer(dataset, tile)
        return TileResult(start + end + labels, len(cs), float(z), float(scales[0]))

    def untangle_morph(
        self,
        parts: MorphParts,
        drawn: TileLines,
        runs: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]],
        ts: NDArray[np.float64],
        bounds: Bounds,
    ) -> MorphParts:
        """The morph tile's parts with the contours that would meet while a client morphs them held still
        (:mod:`engine.tiles.morph_untangle`), each at its snap-rounded shape at the level's end: every contour of
        the tile is shown there (a ring may not be yet at the start), so the exact shapes do not meet."""

        def snap() -> MorphParts:
            cut = self.cut_snapped(replace(drawn, slice_t=ts[-1]), runs, bounds)
            if cut is None:
                empty = np.zeros((0, 2), dtype=np.int64)
                return MorphParts(empty, empty, np.zeros(0, np.int64), np.zeros(0, np.int64))
            return MorphParts(cut.pts, cut.pts, cut.part_len, np.repeat(cut.owner, cut.part_count))

        w = morph_weights(np.round(ts, T_DECIMALS))  # the t a client reads: rounded as encoded
        return untangle(parts, w, snap)[0]

    def min_significance(self, box: Bounds) -> float:
        """Rows less significant than half a grid unit cannot move the quantised line (tiles.significance)."""
        return 0.5 * (box.maxx - box.minx) / (self.options.extent + 2 * self.options.buffer_px)

    def cut(self, drawn: TileLines, bounds: Bounds, box: Bounds, snap: bool = True) -> TileParts | None:
        """The tile pipeline after the method: runs of rows that meet ``box``, sliced, thinned, quantised,
        clipped to the buffered tile; None when nothing is left.

        Plain rounding and thinning can make two lines closer than a grid unit cross; a tile where they do is
        cut again by snap rounding, which cannot (:meth:`cut_snapped`, docs/design.md section 4.8); ``snap`` False
        leaves the tile as rounded (a method whose lines cross by themselves).
        """
        runs = runs_meeting(drawn, box)
        if runs is None:
            return None
        parts = self.cut_rounded(drawn, runs, bounds)
        if parts is not None and snap and self.options.snap_rounding:
            if lines_cross_in_grid(parts.pts, parts.part_len, np.repeat(parts.owner, parts.part_count)):
                return self.cut_snapped(drawn, runs, bounds)
        return parts

    def cut_snapped(
        self, drawn: TileLines, runs: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]], bounds: Bounds
    ) -> TileParts | None:
        """Every row of the runs sliced exactly, clipped to the buffered tile, then snap-rounded all together
        (:mod:`engine.tiles.snap_round`): no two lines cross properly unless their exact slices do. Rows are
        thinned only where they collapse into one grid point."""
        opts = self.options
        a, b, run_owner = runs
        lines = drawn.lines
        pts, plen = slice_runs_exact(a, b, drawn.slice_t[run_owner], lines.base, lines.top, bounds, opts.extent)
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        c_pts, c_len, c_src = clip_lines_exact(pts, plen, lo, hi)
        q, q_len, q_src = snap_round(c_pts, c_len)
        if len(q_len) == 0:
            return None
        part_owner = run_owner[c_src[q_src]]
        order = np.argsort(part_owner, kind="stable")
        q_start = np.cumsum(q_len) - q_len
        part_len = q_len[order]
        out = q[ranges(q_start[order], q_start[order] + part_len)]
        owners, counts = np.unique(part_owner, return_counts=True)
        return TileParts(out, part_len, counts, owners)

    def cut_rounded(
        self, drawn: TileLines, runs: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]], bounds: Bounds
    ) -> TileParts | None:
        """Runs sliced, thinned by significance and rounded to the grid one point at a time, then clipped.

        Every step runs over all the tile's lines at once; only the pieces crossing the buffered tile's edge
        are clipped.
        """
        opts = self.options
        lines = drawn.lines
        a, b, run_owner = runs
        box = buffered(bounds, opts.buffer_px, opts.extent)
        q, plen, pbox = slice_runs(
            a,
            b,
            drawn.slice_t[run_owner],
            drawn.column[run_owner],
            drawn.refill[run_owner],
            lines.sig,
            lines.base,
            lines.top,
            self.min_significance(box),
            bounds,
            opts.extent,
        )
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        pstart = np.cumsum(plen) - plen
        inside = (pbox[:, 0] >= lo) & (pbox[:, 1] >= lo) & (pbox[:, 2] <= hi) & (pbox[:, 3] <= hi)
        valid = plen >= 2
        k_in = np.flatnonzero(valid & inside)
        k_cross = np.flatnonzero(valid & ~inside)
        if len(k_cross):
            cross_pts = q[ranges(pstart[k_cross], pstart[k_cross] + plen[k_cross])]
            c_pts, c_len, c_src = clip_lines_fast(cross_pts, plen[k_cross], lo, hi)
            k_clip = k_cross[c_src]
        else:
            c_pts, c_len, k_clip = np.zeros((0, 2), dtype=np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        if len(k_in) + len(k_clip) == 0:
            return None
        # Parts of a feature: its pieces wholly inside, then the clipped ones, each in line order.
        part_owner = np.concatenate([run_owner[k_in], run_owner[k_clip]])
        part_group = np.concatenate([np.zeros(len(k_in), np.int8), np.ones(len(k_clip), np.int8)])
        part_start = np.concatenate([pstart[k_in], len(q) + np.cumsum(c_len) - c_len])
        part_len = np.concatenate([plen[k_in], c_len])
        order = np.lexsort((part_group, part_owner))
        part_owner, part_start, part_len = part_owner[order], part_start[order], part_len[order]
        all_pts = np.concatenate([q, c_pts]) if len(c_pts) else q
        pts = all_pts[ranges(part_start, part_start + part_len)]
        owners, counts = np.unique(part_owner, return_counts=True)
        return TileParts(pts, part_len, counts, owners)


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


def runs_meeting(
    drawn: TileLines, box: Bounds
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]] | None:
    """Runs of rows [a, b) of the drawn lines whose chunks meet ``box`` (consecutive chunks merged), with the
    contour each run belongs to (runs grouped by contour, in line order); None when no chunk meets it."""
    lines = drawn.lines
    which = drawn.which
    c_lo, c_hi = lines.chunk_off[which], lines.chunk_off[which + 1]
    ci = ranges(c_lo, c_hi)
    ch = lines.chunks[ci]
    hit = (ch[:, 2] >= box.minx) & (ch[:, 0] <= box.maxx) & (ch[:, 3] >= box.miny) & (ch[:, 1] <= box.maxy)
    h = np.flatnonzero(hit)
    if len(h) == 0:
        return None
    owner_of_chunk = np.repeat(np.arange(len(which)), c_hi - c_lo)
    hc, own = ci[h], owner_of_chunk[h]
    cut = np.flatnonzero((np.diff(hc) != 1) | (np.diff(own) != 0))
    first = np.concatenate([[0], cut + 1])
    last = np.concatenate([cut, [len(h) - 1]])
    run_owner = own[first]
    c = which[run_owner]
    row0 = lines.off[c]
    size = lines.chunk_rows
    a = row0 + (hc[first] - lines.chunk_off[c]) * size
    b = np.minimum(row0 + (hc[last] - lines.chunk_off[c] + 1) * size + 1, lines.off[c + 1])
    return a, b, run_owner
