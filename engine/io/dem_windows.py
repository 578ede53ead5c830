"""Contours of a DEM too large to hold whole: traced window by window and joined exactly across window edges.

Why the joins are exact (docs/design.md section 6, "Large DEMs in windows"): neighbouring windows share one
row or column of grid nodes, so the marching-squares cells of the grid are split between the windows with
none left out and none traced twice. contourpy places a line's vertex on a cell edge from the heights of that
edge's two nodes only, so a line leaving one window through the shared row ends at the very point where the
line in the next window starts. The reader joins the two pieces there and keeps that vertex once: the result
has the vertices a whole-grid trace gives, no gap, no duplicate and no kink, so CCSM sees the same lines
whichever window size was used. Lines are joined, not split at window edges, because a split would pin a
vertex of the line at every window edge at every scale.

Only one window of heights is in memory at a time; the windows can be traced on a process pool or a Dask
cluster (:mod:`engine.parallel`). The traced pieces wait, level by level, in the reader's scratch file when
one is given (:class:`~engine.scratch.ReadScratch`), and the levels are joined one at a time as they are
read on, so the whole DEM's lines are never in memory at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import rasterio
from numpy.typing import NDArray
from rasterio.errors import RasterioError
from rasterio.windows import Window
from scipy.spatial import cKDTree

from engine.errors import InvalidParameter, SourceError
from engine.io.dem_tracing import LevelLines, contour_levels, iter_levels
from engine.io.unreadable import unreadable_message
from engine.parallel import map_ordered
from engine.scratch import ReadScratch

#: Window side in cells when the caller gives none: 2049 × 2049 float64 heights are 34 MB.
DEFAULT_BLOCK = 2048

#: Rasters with more cells than this are read in windows; smaller ones whole (a 4096² grid is 134 MB).
WINDOWED_ABOVE_CELLS = 4096 * 4096

#: Two piece ends closer than this (in pixels) are the same vertex traced from both sides of a window edge.
#: Both sides compute it from the same two node heights, so they agree to rounding (about 1e-12 pixel).
JOIN_TOLERANCE_PX = 1e-6


@dataclass(frozen=True)
class RasterHeader:
    """What the windowed reader needs to know of a raster before reading any height, and the band's unit."""

    rows: int
    cols: int
    transform: tuple[float, float, float, float, float, float]
    crs_wkt: str
    tile_shape: tuple[int, int] | None  # internal tiles (rows, cols) of a tiled GeoTIFF, else None
    band_unit: str | None = None  # GDAL's ``units`` of band 1, when the raster states one


class WindowSource(Protocol):
    """A DEM read window by window: a raster file (:class:`~engine.io.raster_windows.RasterDem`) or a tile
    pyramid's mosaic (:class:`~engine.io.terrain_tiles.TileMosaic`). Plain data, so that a worker process can
    read its own windows."""

    @property
    def name(self) -> str:
        """What to call the source in messages."""
        ...

    def header(self) -> RasterHeader:
        """Size, geotransform, CRS and internal tiling of the grid."""
        ...

    def read(self, window: Window) -> np.ma.MaskedArray:
        """The heights of one window of the grid (float64, masked where there is no data)."""
        ...


def read_header(path: Path) -> RasterHeader:
    """Size, geotransform, CRS, internal tiling and band unit of a raster.

    Raises
    ------
    SourceError
        Unreadable file or no CRS.
    """
    try:
        with rasterio.open(path) as src:
            if src.crs is None:
                hint = " (is the .prj file missing?)" if path.suffix.lower() == ".asc" else ""
                raise SourceError(f"{path}: the DEM has no CRS{hint}")
            t = src.transform
            tiled = bool(src.profile.get("tiled", False))
            return RasterHeader(
                rows=src.height,
                cols=src.width,
                transform=(t.a, t.b, t.c, t.d, t.e, t.f),
                crs_wkt=src.crs.to_wkt(),
                tile_shape=tuple(src.block_shapes[0]) if tiled else None,  # type: ignore[arg-type]
                band_unit=(src.units or (None,))[0],
            )
    except RasterioError as exc:
        raise SourceError(unreadable_message(path, "a DEM", exc)) from exc


def window_side(path: Path, block: int | None) -> int | None:
    """The window side to trace the raster ``path`` with: ``block`` when given, else :data:`DEFAULT_BLOCK` for a
    raster of more than :data:`WINDOWED_ABOVE_CELLS` cells, or None to trace a smaller one whole."""
    if block is not None:
        return block
    header = read_header(path)
    return DEFAULT_BLOCK if header.rows * header.cols > WINDOWED_ABOVE_CELLS else None


def window_starts(n: int, block: int) -> list[int]:
    """First node index of each window along an axis of ``n`` nodes; window k spans starts[k] .. starts[k+1].

    >>> window_starts(10, 4)
    [0, 4, 8, 9]
    """
    starts = list(range(0, n - 1, block))
    return [*starts, n - 1]


def windows(header: RasterHeader, block: int) -> Iterator[Window]:
    """Windows of about ``block`` cells a side, row by row, sharing their edge row and column of nodes.

    In a tiled GeoTIFF the side is rounded up to whole internal tiles, so a window reads each tile once (and
    one row and column of the next).
    """
    rows_step = cols_step = block
    if header.tile_shape is not None:
        th, tw = header.tile_shape
        rows_step, cols_step = -(-block // th) * th, -(-block // tw) * tw
    row_edges = window_starts(header.rows, rows_step)
    col_edges = window_starts(header.cols, cols_step)
    for r0, r1 in zip(row_edges[:-1], row_edges[1:], strict=True):
        for c0, c1 in zip(col_edges[:-1], col_edges[1:], strict=True):
            yield Window(c0, r0, c1 - c0 + 1, r1 - r0 + 1)


def trace_window(
    source: str | WindowSource, window: Window, interval: float
) -> tuple[list[LevelLines], float, float]:
    """The lines of one window in whole-grid index space, and the window's height range (nan, nan if empty).

    A module-level function of plain arguments, so a worker process or a Dask worker can run it.
    """
    if isinstance(source, str):
        try:
            with rasterio.open(source) as src:
                z = np.ma.masked_invalid(src.read(1, window=window, masked=True).astype(np.float64))
        except RasterioError as exc:  # on a worker that does not see the file the build read, say so by name
            raise SourceError(unreadable_message(Path(source), "a DEM", exc)) from exc
    else:
        z = np.ma.masked_invalid(source.read(window))
    if z.count() == 0:
        return [], float("nan"), float("nan")
    zmin, zmax = float(z.min()), float(z.max())
    shift = np.array([window.col_off, window.row_off], dtype=np.float64)
    levels = contour_levels(zmin, zmax, interval)
    traced = [(level, [line + shift for line in lines]) for level, lines in iter_levels(z, levels)]
    return traced, zmin, zmax


def join_pieces(pieces: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """Join the pieces of one level that meet end to start into whole lines, keeping each shared vertex once.

    Pieces come in window order. Rings closed within a window and lines from their first piece come first,
    in that order, then rings cut by window edges: the same order on every run and on every executor. A
    closed ring repeats its first vertex at the end, as contourpy's rings do.
    """
    is_open = np.array([not np.array_equal(p[0], p[-1]) for p in pieces])
    open_ids = np.flatnonzero(is_open)
    successor = np.full(len(pieces), -1, dtype=np.intp)
    if len(open_ids) > 1:
        starts = np.array([pieces[i][0] for i in open_ids])
        ends = np.array([pieces[i][-1] for i in open_ids])
        dist, hit = cKDTree(starts).query(ends, distance_upper_bound=JOIN_TOLERANCE_PX)
        found = np.isfinite(dist)
        successor[open_ids[found]] = open_ids[hit[found]]
    has_predecessor = np.zeros(len(pieces), dtype=bool)
    has_predecessor[successor[successor >= 0]] = True
    done = np.zeros(len(pieces), dtype=bool)
    lines: list[NDArray[np.float64]] = []
    # First pass: whole rings and lines from their first piece; second pass: what is left are cut rings.
    for first_pass in (True, False):
        for i in range(len(pieces)):
            if done[i] or (first_pass and has_predecessor[i]):
                continue
            chain = [i]
            done[i] = True
            while successor[chain[-1]] >= 0 and not done[successor[chain[-1]]]:
                chain.append(int(successor[chain[-1]]))
                done[chain[-1]] = True
            line = np.vstack([pieces[chain[0]], *(pieces[k][1:] for k in chain[1:])])
            if not first_pass:
                line[-1] = line[0]  # a ring cut by window edges: closed on its first vertex exactly
            lines.append(line)
    return lines


def contour_windows(
    path: Path | WindowSource,
    interval: float,
    *,
    block: int = DEFAULT_BLOCK,
    executor: Executor | None = None,
    scratch: ReadScratch | None = None,
) -> tuple[Iterator[LevelLines], RasterHeader]:
    """Trace a raster DEM window by window (see the module's docstring); its lines joined level by level.

    ``path`` is a raster file, or any :class:`WindowSource` (a remote or cropped raster, a tile mosaic).

    Every window is traced before this returns (so an unusable DEM fails here); the levels are joined as the
    returned iterator is read, in increasing order. With ``scratch``, the traced pieces wait there rather
    than in memory.

    Returns
    -------
    (levels, header)
        Each level's lines in whole-grid index space as :func:`engine.io.dem_tracing.iter_levels` gives them, and
        the grid's header (its geotransform and CRS).

    Raises
    ------
    InvalidParameter
        ``block`` is below 1, or the interval gives more than :data:`~engine.io.dem_tracing.MAX_LEVELS` levels.
    SourceError
        Unreadable file, no CRS, no valid height or no contour.
    """
    if block < 1:
        raise InvalidParameter(f"block {block} must be at least 1 cell")
    header = read_header(path) if isinstance(path, Path) else path.header()
    # The absolute path: a Dask worker runs in a directory of its own.
    source: str | WindowSource = str(path.resolve()) if isinstance(path, Path) else path
    if header.rows < 2 or header.cols < 2:
        raise SourceError(f"{path.name}: a DEM needs at least 2 x 2 cells, got {header.rows} x {header.cols}")
    tasks = ((source, w, interval) for w in windows(header, block))
    pieces = _LevelPieces(scratch)
    zmin, zmax = np.inf, -np.inf
    for traced, lo, hi in map_ordered(executor, trace_window, tasks):
        zmin, zmax = np.fmin(zmin, lo), np.fmax(zmax, hi)
        for level, lines in traced:
            pieces.extend(level, lines)
    if not np.isfinite(zmin):
        raise SourceError(f"{path.name}: the DEM has no valid heights")
    contour_levels(float(zmin), float(zmax), interval)  # raises InvalidParameter beyond MAX_LEVELS levels
    if not pieces.levels:
        raise SourceError(
            f"{path.name}: no contour at interval {interval:g} within the DEM's range [{zmin:g}, {zmax:g}]"
        )
    return ((level, join_pieces(pieces.pop(level))) for level in sorted(pieces.levels)), header


class _LevelPieces:
    """Traced pieces by level, in window order: in a scratch file when given, else in memory. A level's
    pieces are let go as soon as they are taken to be joined."""

    def __init__(self, scratch: ReadScratch | None) -> None:
        self.scratch = scratch
        self.levels: set[float] = set()
        self._held: dict[float, list[NDArray[np.float64]]] = {}

    def extend(self, level: float, lines: list[NDArray[np.float64]]) -> None:
        self.levels.add(level)
        if self.scratch is not None:
            self.scratch.extend(self._name(level), lines)
        else:
            self._held.setdefault(level, []).extend(lines)

    def pop(self, level: float) -> list[NDArray[np.float64]]:
        if self.scratch is None:
            return self._held.pop(level)
        lines = list(self.scratch.read(self._name(level)))
        self.scratch.drop(self._name(level))
        return lines

    @staticmethod
    def _name(level: float) -> str:
        return f"pieces {level!r}"
