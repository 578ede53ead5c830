"""Tiles and /simplify output from a store: the per-request work, none of which scales with the dataset.

A tile is: R*Tree lookup of the buffered tile -> per contour t from its t(scale) table at the tile's scale
-> slice ``(1 - t) base + t top`` (EPSG:3857) -> quantise to the tile grid (dropping repeated points) ->
clip to the buffered tile -> encode. Decoded contour rows are kept in an LRU cache, and so are the baseline
simplifiers' results per (contour, method, scale step), since Wang–Müller is pure Python.

For ccsm and original tiles, a dataset that fits the contour memory is held as one :class:`DatasetPack`
(every contour's rows, significance, chunk boxes and t tables concatenated, built once per data version), so
that a tile costs a fixed number of NumPy calls plus one compiled pass over the rows it touches, whatever the
number of contours in it (:meth:`Renderer._packed_tile`); the per-request work still follows the R*Tree
lookup and the chunks that meet the tile, not the dataset's size. A larger dataset goes contour by contour
through the LRU cache (the same tiles, more Python per contour).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.similarity import similarity
from engine.errors import InvalidParameter
from engine.geom.polyline import closed_path
from engine.io.crs import WEB_MERCATOR, make_transformer
from engine.store.sqlite import CCSStore, ContourRecord, DatasetInfo
from engine.tiles.grid import (
    CHUNK_ROWS,
    Bounds,
    Tile,
    buffered,
    check_fractional_zoom,
    check_tile,
    chunk_bounds,
    chunk_bounds_packed,
    clip_lines_fast,
    clip_many,
    collinear_free,
    lonlat_to_mercator,
    mercator_to_lonlat,
    quantize,
    ranges,
    row_runs_many,
    slice_runs,
    tile_bounds,
    tile_center_latitude,
)
from engine.tiles.mvt import LineFeature, encode_line_tile, encode_tile
from engine.tiles.scale import scale_for_zoom
from engine.tiles.significance import row_significance
from engine.types import METHODS, Coords

#: Largest scale denominator /simplify accepts (1:10 billion is already smaller than a whole-earth map).
MAX_SCALE = 1e10
#: Baseline results are cached per 1/16 of a zoom level of scale: a 4 % step, invisible on screen.
SCALE_STEPS_PER_OCTAVE = 16
#: Index contours are every 5th interval.
INDEX_EVERY = 5
#: Decimals of the ``t`` property (1e-4 of the source-to-target range is far below a pixel).
T_DECIMALS = 4

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LRUCache(Generic[K, V]):
    """A thread-safe least-recently-used cache bounded by a total cost (entries or bytes)."""

    def __init__(self, max_cost: int, cost: Callable[[V], int] = lambda v: 1) -> None:
        self.max_cost = max_cost
        self._cost = cost
        self._data: OrderedDict[K, tuple[V, int]] = OrderedDict()
        self._total = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, key: K) -> V | None:
        """The cached value, or None."""
        with self._lock:
            item = self._data.get(key)
            if item is None:
                self.misses += 1
                return None
            self._data.move_to_end(key)
            self.hits += 1
            return item[0]

    def put(self, key: K, value: V) -> None:
        """Store a value, evicting the least recently used ones beyond ``max_cost``."""
        c = self._cost(value)
        with self._lock:
            old = self._data.pop(key, None)
            if old is not None:
                self._total -= old[1]
            self._data[key] = (value, c)
            self._total += c
            while self._total > self.max_cost and len(self._data) > 1:
                _, (_, oc) = self._data.popitem(last=False)
                self._total -= oc

    def clear(self) -> None:
        """Drop everything."""
        with self._lock:
            self._data.clear()
            self._total = 0

    def __len__(self) -> int:
        return len(self._data)

    @property
    def total_cost(self) -> int:
        """Sum of the costs of the cached values."""
        return self._total


@dataclass(frozen=True)
class TileOptions:
    """How tiles are cut: grid size, buffer (grid units), layer name, served zoom range."""

    extent: int = 4096
    buffer_px: int = 64
    layer: str = "contours"
    min_zoom: int = 0
    max_zoom: int = 16


@dataclass(frozen=True)
class TileResult:
    """A rendered tile: MVT bytes (None when it has no feature), the zoom and scale it was drawn at."""

    data: bytes | None
    features: int
    zoom: float
    scale: float


@dataclass(frozen=True)
class SimplifiedContour:
    """One contour of a /simplify answer: longitude/latitude coordinates (a ring as a closed path)."""

    fid: int
    contour_id: str
    elevation: float
    t: float
    similarity: float
    coords_lonlat: Coords


def check_method(method: str) -> str:
    """Validate a method name.

    Raises
    ------
    InvalidParameter
        Not one of ccsm, dp, wm, vw, original.
    """
    if method not in METHODS:
        raise InvalidParameter(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    return method


def check_scale(scale: float) -> float:
    """Validate a scale denominator: finite, > 0 and at most MAX_SCALE."""
    value = float(scale)
    if not math.isfinite(value) or value <= 0 or value > MAX_SCALE:
        raise InvalidParameter(f"scale {scale} must be a positive number up to {MAX_SCALE:g}")
    return value


def check_t_override(t: float | None) -> float | None:
    """Validate a hand-pinned t (None = from the scale)."""
    if t is None:
        return None
    value = float(t)
    if not math.isfinite(value) or not 0.0 <= value <= 1.0:
        raise InvalidParameter(f"t {t} must lie in [0, 1]")
    return value


def check_bbox(bbox: Sequence[float]) -> Bounds:
    """Validate a (west, south, east, north) bbox in degrees."""
    if len(bbox) != 4:
        raise InvalidParameter(f"bbox needs 4 numbers west,south,east,north; got {len(bbox)}")
    w, s, e, n = (float(v) for v in bbox)
    if not all(math.isfinite(v) for v in (w, s, e, n)):
        raise InvalidParameter("bbox values must be finite numbers")
    if not (-180 <= w <= 180 and -180 <= e <= 180 and -90 <= s <= 90 and -90 <= n <= 90):
        raise InvalidParameter(f"bbox {w},{s},{e},{n} lies outside longitude [-180, 180] / latitude [-90, 90]")
    if w > e or s > n:
        raise InvalidParameter(f"bbox {w},{s},{e},{n} has min > max (expected west,south,east,north)")
    return Bounds(w, s, e, n)


def infer_interval(elevations: NDArray[np.float64]) -> float | None:
    """The most common difference between sorted distinct elevations."""
    levels = np.unique(np.round(elevations, 6))
    if len(levels) < 2:
        return None
    steps, counts = np.unique(np.round(np.diff(levels), 6), return_counts=True)
    return float(steps[np.argmax(counts)])


def is_index(elevation: float, interval: float | None) -> bool:
    """True when the elevation is a multiple of INDEX_EVERY intervals."""
    if not interval:
        return False
    q = elevation / (INDEX_EVERY * interval)
    return abs(q - round(q)) < 1e-6


def t_at_scales(ladder: NDArray[np.float64], tables: NDArray[np.float64], scale: float) -> NDArray[np.float64]:
    """Each row of ``tables`` ((n, S) t at the ladder's scales) interpolated at one scale, as ``t_for_scale``.

    The interpolation weights depend on the ladder and the scale only, so they are found once for all rows.
    """
    logs = np.log(ladder)
    x = math.log(scale)
    if x <= logs[0]:
        return np.zeros(len(tables))  # at and above the source scale: full detail
    if x >= logs[-1]:
        return tables[:, -1].copy()
    i = int(np.searchsorted(logs, x, side="right")) - 1
    f = (x - logs[i]) / (logs[i + 1] - logs[i])
    return tables[:, i] * (1 - f) + tables[:, i + 1] * f


def _significant(sig: NDArray[np.float32], a: int, b: int, min_sig: float) -> NDArray[np.intp]:
    """Indices in [a, b) of the rows more significant than ``min_sig``, both ends of the range included."""
    keep = sig[a:b] > min_sig
    keep[0] = True
    keep[-1] = True
    return np.flatnonzero(keep) + a


@dataclass(frozen=True)
class PreparedContour:
    """A stored contour plus what speeds up its tiles: chunk boxes of its rows and its target's corners."""

    rec: ContourRecord
    chunks: NDArray[np.float64]
    original_chunks: NDArray[np.float64]
    top_reduced: NDArray[np.float64]

    @classmethod
    def of(cls, rec: ContourRecord) -> PreparedContour:
        """Prepare a decoded row."""
        return cls(
            rec,
            chunk_bounds([rec.base, rec.top]),
            chunk_bounds([rec.original]),
            rec.top[collinear_free(rec.top)],
        )

    @property
    def nbytes(self) -> int:
        """Memory held."""
        return self.rec.nbytes + self.chunks.nbytes + self.original_chunks.nbytes + self.top_reduced.nbytes


@dataclass(frozen=True)
class PackedLines:
    """The rows of many lines concatenated, with per-line offsets, row significance and chunk boxes.

    Attributes
    ----------
    off
        (n + 1,) row offsets: line i is rows [off[i], off[i + 1]).
    sig
        (M,) or (M, k) float32 significance of each row (columns: alternatives chosen per line).
    chunk_off, chunks
        (n + 1,) offsets into (C, 4) chunk boxes (:func:`engine.tiles.grid.chunk_bounds` of each line).
    """

    off: NDArray[np.int64]
    sig: NDArray[np.float32]
    chunk_off: NDArray[np.int64]
    chunks: NDArray[np.float64]

    @classmethod
    def of(cls, sizes: Sequence[int], sig: NDArray[np.float32], rows: Sequence[NDArray[np.float64]]) -> PackedLines:
        """Offsets and chunk boxes of concatenated lines (``rows``: the (M, 2) arrays the chunks cover)."""
        off = np.concatenate([[0], np.cumsum(np.asarray(sizes, dtype=np.int64))]).astype(np.int64)
        if len(sizes) == 0:
            return cls(off, sig, np.zeros(1, np.int64), np.zeros((0, 4)))
        chunks, chunk_off = chunk_bounds_packed(rows, off)
        return cls(off, sig, chunk_off, chunks)

    @property
    def nbytes(self) -> int:
        """Memory held."""
        return int(self.off.nbytes + self.sig.nbytes + self.chunk_off.nbytes + self.chunks.nbytes)


@dataclass(frozen=True)
class DatasetPack:
    """Every contour of one dataset version in a few big arrays, so that a tile is a handful of NumPy calls.

    Contour ``i`` (in fid order) has CCS rows ``base[ccs.off[i]:ccs.off[i + 1]]`` (and ``top``), original
    rows ``original[orig.off[i]:orig.off[i + 1]]``; ``ccs.sig`` has two columns: the significance of the
    (base, top) rows together (valid at every t) and of ``top`` alone (for contours drawn at t = 1).
    """

    data_version: int
    fid: NDArray[np.int64]
    vanish: NDArray[np.float64]
    elevation: NDArray[np.float64]
    index: NDArray[np.bool_]
    tables: NDArray[np.float64]
    base: NDArray[np.float64]
    top: NDArray[np.float64]
    ccs: PackedLines
    original: NDArray[np.float64]
    orig: PackedLines

    @classmethod
    def of(cls, data_version: int, recs: Sequence[ContourRecord], interval: float | None) -> DatasetPack:
        """Pack decoded contour rows (in fid order)."""
        z2 = np.zeros((0, 2))
        base = np.ascontiguousarray(np.concatenate([r.base for r in recs])) if recs else z2
        top = np.ascontiguousarray(np.concatenate([r.top for r in recs])) if recs else z2
        original = np.ascontiguousarray(np.concatenate([r.original for r in recs])) if recs else z2
        ccs_sig = np.zeros((0, 2), np.float32)
        orig_sig = np.zeros(0, np.float32)
        if recs:
            ccs_sig = np.ascontiguousarray(
                np.column_stack(
                    [np.concatenate([r.sig for r in recs]), np.concatenate([row_significance(r.top) for r in recs])]
                ),
                dtype=np.float32,
            )
            orig_sig = np.ascontiguousarray(np.concatenate([r.sig_original for r in recs]), dtype=np.float32)
        elevation = np.array([float(r.elevation) for r in recs])
        index_of = {e: is_index(e, interval) for e in set(elevation.tolist())}
        return cls(
            data_version,
            np.array([r.fid for r in recs], dtype=np.int64),
            np.array([r.vanish_scale for r in recs], dtype=np.float64),
            elevation,
            np.array([index_of[e] for e in elevation.tolist()], dtype=bool),
            np.stack([r.t_at_scale for r in recs]) if recs else np.zeros((0, 1)),
            base,
            top,
            PackedLines.of([len(r.base) for r in recs], ccs_sig, [base, top]),
            original,
            PackedLines.of([len(r.original) for r in recs], orig_sig, [original]),
        )

    @property
    def nbytes(self) -> int:
        """Memory held."""
        arrays = (self.fid, self.vanish, self.elevation, self.index, self.tables, self.base, self.top, self.original)
        return int(sum(a.nbytes for a in arrays) + self.ccs.nbytes + self.orig.nbytes)

    def locate(self, fids: Sequence[int]) -> NDArray[np.intp] | None:
        """Positions of fids (sorted) in the pack; None when one of them is not in it (another version)."""
        f = np.asarray(fids, dtype=np.int64)
        if len(self.fid) == 0:
            return None if len(f) else np.zeros(0, dtype=np.intp)
        pos = np.minimum(np.searchsorted(self.fid, f), len(self.fid) - 1)
        return pos if bool((self.fid[pos] == f).all()) else None


#: Bytes per stored vertex a dataset pack holds, about (to decide whether a dataset fits the contour memory).
PACK_BYTES_PER_VERTEX = 120


class Renderer:
    """Renders tiles and /simplify answers from a store, with in-memory caches.

    Parameters
    ----------
    store
        The store to read.
    options
        Tile grid and zoom range.
    contour_cache_bytes
        Memory for decoded contour rows.
    baseline_cache_entries
        Number of baseline results kept.
    """

    def __init__(
        self,
        store: CCSStore,
        options: TileOptions | None = None,
        *,
        contour_cache_bytes: int = 512 << 20,
        baseline_cache_entries: int = 100_000,
    ) -> None:
        self.store = store
        self.options = options or TileOptions()
        self.contours: LRUCache[int, PreparedContour] = LRUCache(contour_cache_bytes, lambda r: r.nbytes + 1024)
        self.baselines: LRUCache[tuple[int, str, int], tuple[Coords, Coords]] = LRUCache(baseline_cache_entries)
        self._info: dict[str, tuple[DatasetInfo, float | None]] = {}
        self._transformers: dict[str, Callable[[Any], Coords]] = {}
        self.contour_cache_bytes = contour_cache_bytes
        self._packs: dict[str, DatasetPack] = {}
        self._pack_lock = threading.Lock()

    # -- metadata ----------------------------------------------------------------------------------------
    def info(self, dataset: str) -> tuple[DatasetInfo, float | None]:
        """The dataset's metadata and contour interval, cached per data_version.

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
        interval = info.interval
        if not interval:
            con = self.store._con()
            elev = np.array(
                [r[0] for r in con.execute("SELECT DISTINCT elevation FROM contours WHERE dataset=?", (dataset,))]
            )
            interval = infer_interval(elev) if len(elev) else None
        self._info[dataset] = (info, interval)
        return info, interval

    def forget(self, dataset: str) -> None:
        """Drop cached metadata of a dataset (after a delete or rebuild; contour rows get new fids anyway)."""
        self._info.pop(dataset, None)
        self._packs.pop(dataset, None)

    def pack(self, dataset: str, meta: tuple[DatasetInfo, float | None] | None = None) -> DatasetPack | None:
        """The dataset's contours packed for tiles (built once per data version), or None when the dataset is
        larger than the contour memory (tiles then go contour by contour through the LRU cache)."""
        info, interval = meta or self.info(dataset)
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

    def records(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decoded contour rows, from the cache or the store."""
        return [p.rec for p in self.prepared(fids)]

    def prepared(self, fids: Sequence[int]) -> list[PreparedContour]:
        """Decoded contour rows with their chunk indexes, from the cache or the store."""
        out: list[PreparedContour | None] = [self.contours.get(f) for f in fids]
        missing = [f for f, r in zip(fids, out, strict=True) if r is None]
        if missing:
            loaded = {r.fid: PreparedContour.of(r) for r in self.store.load(missing)}
            for f, r in loaded.items():
                self.contours.put(f, r)
            out = [r if r is not None else loaded.get(f) for f, r in zip(fids, out, strict=True)]
        return [r for r in out if r is not None]

    # -- geometry per method -----------------------------------------------------------------------------
    def _baseline(self, info: DatasetInfo, rec: ContourRecord, method: str, scale: float) -> tuple[Coords, Coords]:
        """(EPSG:3857 closed path, working-CRS coordinates) of a baseline's result at a scale (cached)."""
        from engine.baselines import simplify_at_scale

        step = round(math.log2(scale) * SCALE_STEPS_PER_OCTAVE)
        key = (rec.fid, method, step)
        hit = self.baselines.get(key)
        if hit is not None:
            return hit
        snapped = 2.0 ** (step / SCALE_STEPS_PER_OCTAVE)
        result_w = np.asarray(simplify_at_scale(method, rec.original_w, rec.closed, snapped), dtype=np.float64)
        tr = self._transformers.get(info.working_crs)
        if tr is None:
            tr = self._transformers[info.working_crs] = make_transformer(info.working_crs, WEB_MERCATOR)
        result = tr(closed_path(result_w) if rec.closed else result_w)
        value = (result, result_w)
        self.baselines.put(key, value)
        return value

    def _parts(
        self,
        info: DatasetInfo,
        preps: Sequence[PreparedContour],
        ts: NDArray[np.float64],
        method: str,
        scale: float,
        box: Bounds,
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
        """The pieces of every contour's line near ``box`` for a method.

        Returns
        -------
        (xy, lens, owner)
            Concatenated EPSG:3857 coordinates of the pieces, each piece's length, and the index (into
            ``preps``) of the contour each piece belongs to.
        """
        bases: list[NDArray[np.float64]] = []
        tops: list[NDArray[np.float64]] = []
        owner: list[int] = []
        part_t: list[float] = []
        # Rows whose significance is below half a grid unit cannot move the quantised line (engine.tiles.significance).
        min_sig = 0.5 * (box.maxx - box.minx) / (self.options.extent + 2 * self.options.buffer_px)
        if method == "ccsm":
            partial = []
            for i, p in enumerate(preps):
                if ts[i] >= 1.0:  # the target contour: its straight runs need only their end rows
                    bases.append(p.top_reduced)
                    tops.append(p.top_reduced)
                    owner.append(i)
                    part_t.append(0.0)
                else:
                    partial.append(i)
            if partial:
                lines, starts, ends = row_runs_many(
                    [preps[i].chunks for i in partial], [len(preps[i].rec.base) for i in partial], box
                )
                for j, a, b in zip(lines.tolist(), starts.tolist(), ends.tolist(), strict=True):
                    i = partial[j]
                    rec = preps[i].rec
                    rows = _significant(rec.sig, a, b, min_sig)
                    bases.append(rec.base[rows])
                    tops.append(rec.top[rows])
                    owner.append(i)
                    part_t.append(float(ts[i]))
        elif method == "original":
            lines, starts, ends = row_runs_many(
                [p.original_chunks for p in preps], [len(p.rec.original) for p in preps], box
            )
            for i, a, b in zip(lines.tolist(), starts.tolist(), ends.tolist(), strict=True):
                rec = preps[i].rec
                bases.append(rec.original[_significant(rec.sig_original, a, b, min_sig)])
                owner.append(i)
        else:
            for i, p in enumerate(preps):
                bases.append(self._baseline(info, p.rec, method, scale)[0])
                owner.append(i)
        if not bases:
            empty = np.zeros(0, dtype=np.int64)
            return np.zeros((0, 2)), empty, empty
        lens = np.fromiter((len(b) for b in bases), dtype=np.int64, count=len(bases))
        base = np.concatenate(bases)
        if method == "ccsm":
            top = np.concatenate(tops)
            tt = np.repeat(np.asarray(part_t), lens)[:, None]
            xy = base + tt * (top - base)
        else:
            xy = base
        return xy, lens, np.asarray(owner, dtype=np.int64)

    @staticmethod
    def _visible(recs: Sequence[ContourRecord], scale: float, method: str) -> list[int]:
        if method == "original":
            return list(range(len(recs)))
        return [i for i, r in enumerate(recs) if scale < r.vanish_scale]

    def _t_values(
        self, info: DatasetInfo, recs: Sequence[ContourRecord], scale: float, t: float | None
    ) -> NDArray[np.float64]:
        if t is not None:
            return np.full(len(recs), t)
        if not recs:
            return np.zeros(0)
        tables = np.stack([r.t_at_scale for r in recs])
        return t_at_scales(info.ladder, tables, scale)

    # -- tiles -------------------------------------------------------------------------------------------
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
        return tile, zoomf, check_t_override(t)

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
        info, interval = self.info(dataset)
        opts = self.options
        bounds = tile_bounds(tile)
        box = buffered(bounds, opts.buffer_px, opts.extent)
        scale = self.scale_of_tile(tile, zoomf)
        fids = self.store.query(dataset, box)
        if not fids:
            return TileResult(None, 0, zoomf, scale)
        if method in ("ccsm", "original"):
            pack = self.pack(dataset, (info, interval))
            where = pack.locate(fids) if pack is not None else None
            if pack is not None and where is None:  # the store changed under the pack: take the new version
                self.forget(dataset)
                info, interval = self.info(dataset)
                pack = self.pack(dataset)
                where = pack.locate(fids) if pack is not None else None
            if pack is not None and where is not None:
                data, n = self._packed_tile(pack, where, info, scale, method, t_pin, bounds, box)
                return TileResult(data, n, zoomf, scale)
        preps = self.prepared(fids)
        keep = self._visible([p.rec for p in preps], scale, method)
        preps = [preps[i] for i in keep]
        if not preps:
            return TileResult(None, 0, zoomf, scale)
        recs = [p.rec for p in preps]
        ts = self._t_values(info, recs, scale, t_pin if method == "ccsm" else None)
        xy, lens, owner = self._parts(info, preps, ts, method, scale, box)
        if len(lens) == 0:
            return TileResult(None, 0, zoomf, scale)
        features = self._features(recs, ts, xy, lens, owner, bounds, interval)
        if not features:
            return TileResult(None, 0, zoomf, scale)
        return TileResult(encode_tile({opts.layer: features}, opts.extent), len(features), zoomf, scale)

    def _packed_tile(
        self,
        pack: DatasetPack,
        where: NDArray[np.intp],
        info: DatasetInfo,
        scale: float,
        method: str,
        t_pin: float | None,
        bounds: Bounds,
        box: Bounds,
    ) -> tuple[bytes | None, int]:
        """A ccsm or original tile from the dataset pack: (MVT bytes or None, number of features).

        Every step runs over all the tile's contours at once: chunk culling, row significance, slicing,
        quantising, dropping repeats, the inside test; only pieces crossing the buffered tile's edge go
        through shapely.
        """
        opts = self.options
        idx = where if method == "original" else where[scale < pack.vanish[where]]
        if len(idx) == 0:
            return None, 0
        if method == "ccsm" and t_pin is not None:
            ts = np.full(len(idx), t_pin)
        else:
            ts = t_at_scales(info.ladder, pack.tables[idx], scale)
        lines = pack.ccs if method == "ccsm" else pack.orig
        # Chunks of the tile's contours that meet the box, merged into runs of rows.
        c_lo, c_hi = lines.chunk_off[idx], lines.chunk_off[idx + 1]
        ci = ranges(c_lo, c_hi)
        ch = lines.chunks[ci]
        hit = (ch[:, 2] >= box.minx) & (ch[:, 0] <= box.maxx) & (ch[:, 3] >= box.miny) & (ch[:, 1] <= box.maxy)
        h = np.flatnonzero(hit)
        if len(h) == 0:
            return None, 0
        owner_of_chunk = np.repeat(np.arange(len(idx)), c_hi - c_lo)
        hc, own = ci[h], owner_of_chunk[h]
        cut = np.flatnonzero((np.diff(hc) != 1) | (np.diff(own) != 0))
        first = np.concatenate([[0], cut + 1])
        last = np.concatenate([cut, [len(h) - 1]])
        run_owner = own[first]
        c = idx[run_owner]
        row0 = lines.off[c]
        a = row0 + (hc[first] - lines.chunk_off[c]) * CHUNK_ROWS
        b = np.minimum(row0 + (hc[last] - lines.chunk_off[c] + 1) * CHUNK_ROWS + 1, lines.off[c + 1])
        # Rows whose significance is below half a grid unit cannot move the quantised line (engine.tiles.significance).
        min_sig = 0.5 * (box.maxx - box.minx) / (opts.extent + 2 * opts.buffer_px)
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        if method == "ccsm":
            run_t = ts[run_owner]
            # Drawn at the target: the target's own significance decides, and a contour smaller than a grid
            # cell keeps all its rows so that it shows as the full line does instead of vanishing.
            at_top = run_t >= 1.0
            q, plen, pbox = slice_runs(
                a,
                b,
                run_t,
                at_top.astype(np.int64),
                at_top,
                lines.sig,
                pack.base,
                pack.top,
                min_sig,
                bounds,
                opts.extent,
            )
        else:
            zeros = np.zeros(len(a))
            q, plen, pbox = slice_runs(
                a,
                b,
                zeros,
                np.zeros(len(a), np.int64),
                np.zeros(len(a), bool),
                lines.sig.reshape(-1, 1),
                pack.original,
                pack.original,
                min_sig,
                bounds,
                opts.extent,
            )
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
        n_parts = len(k_in) + len(k_clip)
        if n_parts == 0:
            return None, 0
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
        cs = idx[owners]
        columns = {
            "elevation": pack.elevation[cs].tolist(),
            "index": pack.index[cs].tolist(),
            "t": [round(v, T_DECIMALS) for v in ts[owners].tolist()],
        }
        data = encode_line_tile(opts.layer, pack.fid[cs].tolist(), columns, pts, part_len, counts, opts.extent)
        return data, len(owners)

    def _features(
        self,
        recs: Sequence[ContourRecord],
        ts: NDArray[np.float64],
        xy: NDArray[np.float64],
        lens: NDArray[np.int64],
        owner: NDArray[np.int64],
        bounds: Bounds,
        interval: float | None,
    ) -> list[LineFeature]:
        opts = self.options
        q = quantize(xy, bounds, opts.extent)
        # Drop consecutive repeats inside each piece (the first point of every piece always stays).
        keep = np.empty(len(q), dtype=bool)
        keep[0] = True
        np.any(q[1:] != q[:-1], axis=1, out=keep[1:])
        starts = np.cumsum(lens) - lens
        keep[starts] = True
        piece = np.repeat(np.arange(len(lens)), lens)[keep]
        q = q[keep]
        new_lens = np.bincount(piece, minlength=len(lens))
        new_starts = np.cumsum(new_lens) - new_lens
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        mins = np.minimum.reduceat(q.min(axis=1), new_starts)
        maxs = np.maximum.reduceat(q.max(axis=1), new_starts)
        inside = ((mins >= lo) & (maxs <= hi)).tolist()
        new_lens_l = new_lens.tolist()
        new_starts_l = new_starts.tolist()
        by_owner: dict[int, list[NDArray[np.int64]]] = {}
        to_clip: list[NDArray[np.int64]] = []
        to_clip_owner: list[int] = []
        for k, i in enumerate(owner.tolist()):
            n = new_lens_l[k]
            if n < 2:
                continue
            s = new_starts_l[k]
            line = q[s : s + n]
            if inside[k]:
                by_owner.setdefault(i, []).append(line)
            else:
                to_clip.append(line)
                to_clip_owner.append(i)
        for i, parts in zip(to_clip_owner, clip_many(to_clip, lo, hi), strict=True):
            if parts:
                by_owner.setdefault(i, []).extend(parts)
        by_owner = dict(sorted(by_owner.items()))
        features = []
        index_cache: dict[float, bool] = {}
        for i, parts in by_owner.items():
            rec = recs[i]
            elev = float(rec.elevation)
            idx = index_cache.get(elev)
            if idx is None:
                idx = index_cache[elev] = is_index(elev, interval)
            features.append(
                LineFeature(rec.fid, parts, {"elevation": elev, "index": idx, "t": round(float(ts[i]), T_DECIMALS)})
            )
        return features

    # -- /simplify ---------------------------------------------------------------------------------------
    def simplify(
        self,
        dataset: str,
        scale: float,
        *,
        bbox_lonlat: Sequence[float] | None = None,
        method: str = "ccsm",
    ) -> list[SimplifiedContour]:
        """Every visible contour of a dataset at a scale denominator, in longitude/latitude.

        Parameters
        ----------
        dataset
            Stored dataset id.
        scale
            Scale denominator, > 0 (any value: t is interpolated in each contour's table).
        bbox_lonlat
            (west, south, east, north) degrees: only contours whose extent meets it.
        method
            ccsm, dp, wm, vw or original.

        Raises
        ------
        InvalidParameter, UnknownLayer
        """
        value = check_scale(scale)
        check_method(method)
        bbox = check_bbox(bbox_lonlat) if bbox_lonlat is not None else None
        info, _ = self.info(dataset)
        if bbox is None:
            fids = self.store.all_fids(dataset)
        else:
            xs, ys = lonlat_to_mercator(np.array([bbox.minx, bbox.maxx]), np.array([bbox.miny, bbox.maxy]))
            fids = self.store.query(dataset, (xs[0], ys[0], xs[1], ys[1]))
        recs = self.records(fids)
        recs = [recs[i] for i in self._visible(recs, value, method)]
        if not recs:
            return []
        ts = self._t_values(info, recs, value, None)
        out = []
        for rec, t in zip(recs, ts, strict=True):
            if method == "ccsm":
                xy = rec.base + float(t) * (rec.top - rec.base)
                sim = float(np.interp(t, rec.sim_t, rec.sim))
            elif method == "original":
                xy, sim = rec.original, 1.0
            else:
                xy, xy_w = self._baseline(info, rec, method, value)
                sim = float(similarity(rec.original_w, xy_w, rec.closed))
            lon, lat = mercator_to_lonlat(xy[:, 0], xy[:, 1])
            out.append(
                SimplifiedContour(
                    rec.fid,
                    rec.contour_id,
                    float(rec.elevation),
                    round(float(t), T_DECIMALS),
                    sim,
                    np.column_stack([lon, lat]),
                )
            )
        return out


def feature_collection(
    contours: Sequence[SimplifiedContour], scale: float, method: str, decimals: int = 7
) -> dict[str, Any]:
    """A GeoJSON FeatureCollection (RFC 7946, EPSG:4326) of /simplify results."""
    return {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "id": c.fid,
                "properties": {
                    "id": c.contour_id,
                    "elevation": c.elevation,
                    "t": c.t,
                    "similarity": round(c.similarity, 6),
                    "scale": scale,
                    "method": method,
                },
                "geometry": {
                    "type": "LineString",
                    "coordinates": np.round(c.coords_lonlat, decimals).tolist(),
                },
            }
            for c in contours
        ],
    }
