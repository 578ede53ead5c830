"""Contours from a DEM: GeoTIFF, ESRI ASCII grid, or the ``.npz`` layout of matplotlib's sample DEM."""

from __future__ import annotations

import math
import os
import zipfile
from collections.abc import Iterator
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import pyproj
import rasterio
from numpy.typing import NDArray
from rasterio.errors import RasterioError

from engine.errors import InvalidParameter, SourceError
from engine.intervals import UNIT_NAMES
from engine.io.cleaning import CheckedBatch, LineParts, assemble_batches, check_batch, in_batches
from engine.io.crs import WGS84, parse_crs
from engine.io.dem_tracing import LevelLines, contour_levels, iter_levels, uphill_side
from engine.io.dem_windows import (
    DEFAULT_BLOCK,
    WINDOWED_ABOVE_CELLS,
    WindowSource,
    contour_windows,
    read_header,
    window_side,
)
from engine.io.raster_windows import RasterDem
from engine.io.terrain_tiles import TerrainTiles, open_mosaic
from engine.io.unreadable import unreadable_message
from engine.parallel import map_ordered
from engine.scratch import ReadScratch
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import BadFeature, ContourSet, FeatureId

#: File extensions read as DEMs.
RASTER_SUFFIXES: tuple[str, ...] = (".tif", ".tiff", ".asc")
NPZ_SUFFIXES: tuple[str, ...] = (".npz",)
DEM_SUFFIXES: tuple[str, ...] = RASTER_SUFFIXES + NPZ_SUFFIXES

#: A traced line whose every vertex lies within this many pixels of a grid node is not a contour but a
#: by-product of :data:`~engine.io.dem_tracing.LEVEL_OFFSET`: grid nodes *at* the level (a pit bottom or a
#: flat ridge of whole-metre heights) make the true contour a point or a doubled segment, and tracing 1 mm
#: higher wraps them in a ring a few millimetres wide. Such vertices sit LEVEL_OFFSET / (height step) pixels
#: from the node: at most 0.001 pixel for whole-metre heights; in the sample DEM the next line's farthest
#: vertex is 0.077 pixel off a node. The same distance decides that an open line whose two ends nearly touch
#: (at a node on the data's edge that is exactly at the level) is a ring.
NODE_SNAP_PX = 0.01

#: Pixels added to :data:`NODE_SNAP_PX` when it is compared: on heights in steps of 0.1 m (terrain-RGB) an
#: artefact's vertices sit *exactly* LEVEL_OFFSET / 0.1 m = 0.01 px from the node, and rounding (a window's
#: offset added to its vertices, about 1e-13 px) would decide on which side of the threshold they fall, so the
#: whole grid and its windows would disagree on the same line.
NODE_SNAP_SLACK_PX = 1e-9

#: Keys of the ``.npz`` layout (matplotlib's ``jacksboro_fault_dem.npz``).
NPZ_KEYS: tuple[str, ...] = ("elevation", "xmin", "xmax", "ymin", "ymax", "dx", "dy")

T = TypeVar("T")


@dataclass(frozen=True)
class DemGrid:
    """A DEM in memory.

    Attributes
    ----------
    z
        (rows, cols) float64 heights, masked where there is no data.
    transform
        (a, b, c, d, e, f): the grid corner at column ``u``, row ``v`` (pixel edges, so pixel (r, k) spans
        u in [k, k + 1]) is at x = a·u + b·v + c, y = d·u + e·v + f in ``crs`` (GDAL's geotransform order,
        as in :class:`affine.Affine`).
    crs
        The CRS of the grid.
    """

    z: np.ma.MaskedArray
    transform: tuple[float, float, float, float, float, float]
    crs: pyproj.CRS


def contours_from_dem(
    path: str | os.PathLike[str] | RasterDem | TerrainTiles,
    *,
    interval: float,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    block: int | None = None,
    executor: Executor | None = None,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """Trace contour lines from a DEM at every multiple of ``interval``.

    Parameters
    ----------
    path
        ``.tif`` / ``.tiff`` (GeoTIFF), ``.asc`` (ESRI ASCII grid with its ``.prj``), or ``.npz`` in the
        layout of matplotlib's sample DEM (keys elevation, xmin, xmax, ymin, ymax, dx, dy; EPSG:4326); or a
        :class:`~engine.io.raster_windows.RasterDem` (a GeoTIFF URL, or a raster's area) or
        :class:`~engine.io.terrain_tiles.TerrainTiles` (a tile pyramid's area), always read in windows.
    interval
        Contour interval in the DEM's vertical unit; levels are the multiples of it within the data's range.
    tolerances
        Cleaning distances in metres (see :func:`engine.io.cleaning.assemble_batches`).
    block
        GeoTIFF / ``.asc`` only: trace in windows of about this many cells a side, joined exactly at their
        edges (:mod:`engine.io.dem_windows`). None: as :func:`~engine.io.dem_windows.window_side` chooses by
        the raster's size.
    executor
        Where the windows are traced (see :mod:`engine.parallel`); None = in this process.
    scratch
        Where the traced lines and the contours wait (:class:`~engine.scratch.ReadScratch`), so that the
        memory holds one level at a time; None = in memory.

    Returns
    -------
    ContourSet
        Contours in metres of the working CRS, ``elevation`` the nominal multiple of ``interval`` (lines are
        traced :data:`~engine.io.dem_tracing.LEVEL_OFFSET` above it), ids ``"{elevation}:{k}"`` with k counting
        the lines of that level, closed rings (first == last from contourpy) stored without their repeated vertex,
        ``interval`` set.

    Raises
    ------
    InvalidParameter
        ``interval`` is not a positive number, or gives more than :data:`~engine.io.dem_tracing.MAX_LEVELS`
        levels.
    SourceError
        The file is missing, unreadable, of an unknown format, has no CRS, or yields no contour.
    """
    if not (isinstance(interval, (int, float)) and math.isfinite(interval) and interval > 0):
        raise InvalidParameter(f"interval {interval!r} must be a positive number", parameter="interval")
    if isinstance(path, (RasterDem, TerrainTiles)):
        return _contours_in_windows(
            open_mosaic(path) if isinstance(path, TerrainTiles) else path,
            float(interval),
            stem=path.stem,
            tolerances=tolerances,
            block=block,
            executor=executor,
            scratch=scratch,
        )
    path = Path(path)
    windowed = _windowed_block(path, block)
    batches: Iterator[LineParts | CheckedBatch]
    if windowed is not None:
        levels, header = contour_windows(path, float(interval), block=windowed, executor=executor, scratch=scratch)
        transform, crs = header.transform, parse_crs(header.crs_wkt, where=str(path))
        # One level at a time: its lines mapped to the grid's CRS and handed on in batches.
        batches = (batch for lv in levels for batch in in_batches(line_parts_from_traced([lv], transform, path.name)))
    else:
        grid = read_dem(path)
        crs = grid.crs
        batches = _grid_batches(path, grid, float(interval), executor)
        del grid  # with workers, each reads its own copy: this one is not kept while they trace
    return assemble_batches(
        batches,
        source_crs=crs,
        where=path.name,
        name=path.stem,
        tolerances=tolerances,
        interval=float(interval),
        scratch=scratch,
    )


def _contours_in_windows(
    source: WindowSource,
    interval: float,
    *,
    stem: str,
    tolerances: Tolerances,
    block: int | None,
    executor: Executor | None,
    scratch: ReadScratch | None,
) -> ContourSet:
    """:func:`contours_from_dem` of a source read only in windows (one window for a small grid)."""
    if block is None:
        header = source.header()
        large = header.rows * header.cols > WINDOWED_ABOVE_CELLS
        block = DEFAULT_BLOCK if large else max(header.rows, header.cols)
    levels, header = contour_windows(source, interval, block=block, executor=executor, scratch=scratch)
    crs = parse_crs(header.crs_wkt, where=source.name)
    batches = (
        batch for lv in levels for batch in in_batches(line_parts_from_traced([lv], header.transform, source.name))
    )
    return assemble_batches(
        batches,
        source_crs=crs,
        where=source.name,
        name=stem,
        tolerances=tolerances,
        interval=interval,
        scratch=scratch,
    )


def _windowed_block(path: Path, block: int | None) -> int | None:
    """The window side to read ``path`` with, or None to read it whole (see :func:`contours_from_dem`)."""
    if path.suffix.lower() not in RASTER_SUFFIXES or not path.exists():
        return None
    return window_side(path, block)


def read_dem(path: str | os.PathLike[str]) -> DemGrid:
    """Read a DEM's first band, its geotransform and its CRS.

    Raises
    ------
    SourceError
        Missing or unreadable file, unknown format, missing or unknown CRS.
    """
    path = Path(path)
    if not path.exists():
        raise SourceError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix in NPZ_SUFFIXES:
        return _read_npz(path)
    if suffix in RASTER_SUFFIXES:
        return _read_raster(path)
    raise SourceError(f"{path}: unknown DEM format {path.suffix!r}; expected one of {DEM_SUFFIXES}")


def _read_raster(path: Path) -> DemGrid:
    try:
        with rasterio.open(path) as src:
            if src.crs is None:
                hint = " (is the .prj file missing?)" if path.suffix.lower() == ".asc" else ""
                raise SourceError(f"{path}: the DEM has no CRS{hint}")
            crs = parse_crs(src.crs.to_wkt(), where=str(path))
            z = src.read(1, masked=True).astype(np.float64)
            t = src.transform
            geotransform = (t.a, t.b, t.c, t.d, t.e, t.f)
    except RasterioError as exc:
        raise SourceError(unreadable_message(path, "a DEM", exc)) from exc
    z = np.ma.masked_invalid(z)
    return DemGrid(z=z, transform=geotransform, crs=crs)


def _read_npz(path: Path) -> DemGrid:
    """Read the ``.npz`` layout of matplotlib's ``jacksboro_fault_dem.npz``.

    Row 0 lies at ``ymin`` and column 0 at ``xmin``; rows run towards ``ymax``, columns towards ``xmax``.
    In matplotlib's file ``ymin`` (36.733°) is the *northern* edge, so row 0 is north, as in any image:
    the names describe the array order, not the compass. Checked against the terrain: with row 0 north the
    Pine Mountain ridge runs south-west to north-east and the low Valley and Ridge lies south-east, as on a
    map.

    Pixel centres or edges: in matplotlib's file (xmax - xmin) / dx = 403.000 for 403 columns and
    (ymin - ymax) / dy = 344.000 for 344 rows, so the four values are the outer *edges* of the grid (centres
    would span one pixel less) and the first pixel's centre is half a pixel inside. Other files are judged the
    same way: a span of n pixels means edges, of n - 1 pixels means centres, anything else is an error.
    The CRS is the ``crs`` key when present, else EPSG:4326.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in NPZ_KEYS if k not in data.files]
            if missing:
                raise SourceError(
                    f"{path}: not a DEM .npz: missing keys {missing} (has {sorted(data.files)}; "
                    f"expected {list(NPZ_KEYS)})"
                )
            z = np.asarray(data["elevation"], dtype=np.float64)
            xmin, xmax, ymin, ymax, dx, dy = (
                float(data[k]) for k in ("xmin", "xmax", "ymin", "ymax", "dx", "dy")
            )
            crs_text = str(data["crs"]) if "crs" in data.files else WGS84
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise SourceError(f"{path}: cannot read DEM .npz ({exc})") from exc
    if z.ndim != 2 or min(z.shape) < 2:
        raise SourceError(f"{path}: elevation must be a 2-D grid of at least 2 x 2, got shape {z.shape}")
    if not (dx > 0 and dy > 0):
        raise SourceError(f"{path}: dx and dy must be positive, got {dx}, {dy}")
    rows, cols = z.shape
    x0 = _first_edge(xmin, xmax, dx, cols, "x", path)
    y0 = _first_edge(ymin, ymax, dy, rows, "y", path)
    sx = 1.0 if xmax >= xmin else -1.0
    sy = 1.0 if ymax >= ymin else -1.0
    crs = parse_crs(crs_text, where=str(path))
    return DemGrid(z=np.ma.masked_invalid(z), transform=(sx * dx, 0.0, x0, 0.0, sy * dy, y0), crs=crs)


def _first_edge(v_first: float, v_last: float, step: float, n: int, axis: str, path: Path) -> float:
    """Outer edge of the first pixel along one axis, given the layout's two bounding values."""
    pixels = abs(v_last - v_first) / step
    direction = 1.0 if v_last >= v_first else -1.0
    if math.isclose(pixels, n, abs_tol=1e-3):
        return v_first  # the values are the grid's outer edges (matplotlib's file)
    if math.isclose(pixels, n - 1, abs_tol=1e-3):
        return v_first - direction * step / 2.0  # the values are the first and last pixel centres
    raise SourceError(
        f"{path}: {axis} bounds span {pixels:.3f} pixels of {step} for {n} pixels; cannot tell the grid's geometry"
    )


def _grid_levels(grid: DemGrid, interval: float, where: str) -> tuple[NDArray[np.float64], str]:
    """The levels to trace in ``grid``, and the error to give if none has a line.

    Raises
    ------
    SourceError
        The grid has no valid height.
    """
    z = grid.z
    if z.count() == 0:
        raise SourceError(f"{where}: the DEM has no valid heights")
    zmin, zmax = float(z.min()), float(z.max())
    none_found = f"{where}: no contour at interval {interval:g} within the DEM's range [{zmin:g}, {zmax:g}]"
    return contour_levels(zmin, zmax, interval), none_found


def _at_least_one(levels: Iterator[T], message: str) -> Iterator[T]:
    empty = True
    for level in levels:
        empty = False
        yield level
    if empty:
        raise SourceError(message)


#: A whole grid's levels are traced on the workers in about this many tasks (enough for a few workers)...
LEVEL_TASKS = 8
#: ... of at least this many levels each: every task reads the grid again, which costs about as much as
#: tracing 7 of its levels (2048² cells: 0.15 s against 22 ms a level).
MIN_LEVELS_PER_TASK = 8


def _grid_batches(
    path: Path, grid: DemGrid, interval: float, executor: Executor | None
) -> Iterator[LineParts | CheckedBatch]:
    """The lines of a grid read whole in batches, level by level (levels without a line left out), in the grid's
    CRS: traced here without an executor, else on its workers, a run of levels per task, each batch checked
    there too (:func:`trace_grid_levels`).

    Each worker reads the file again rather than receive the heights: a task then weighs a few bytes, and the
    lines are the very ones this process would trace, since a level's lines depend only on the heights and the
    level. So the tiles are the same whichever executor builds them.
    """
    levels, none_found = _grid_levels(grid, interval, path.name)
    if executor is None:
        parts = _at_least_one(_level_parts(grid, levels, path.name), none_found)
        return (batch for level_parts in parts for batch in in_batches(level_parts))
    stat = path.stat()
    per_task = max(MIN_LEVELS_PER_TASK, math.ceil(len(levels) / LEVEL_TASKS))
    runs = [levels[k : k + per_task].tolist() for k in range(0, len(levels), per_task)]
    # The absolute path: a Dask worker runs in a directory of its own.
    tasks = ((str(path.resolve()), run, (stat.st_size, stat.st_mtime_ns)) for run in runs)
    traced_runs = map_ordered(executor, trace_grid_levels, tasks)
    # Every level with a line makes at least one batch (its lines, or the artefacts it reports).
    return _at_least_one((batch for run in traced_runs for batch in run), none_found)


def trace_grid_levels(path: str, levels: list[float], expected: tuple[int, int]) -> list[CheckedBatch]:
    """The lines of ``levels`` in the DEM at ``path`` read whole, in the grid's CRS, in batches checked in it
    (:func:`~engine.io.cleaning.check_batch`): what :func:`contours_from_dem` traces and checks in this process,
    run on a worker.

    Raises
    ------
    SourceError
        The file is not the one the build read (its size or modification time differ), or cannot be read.
    """
    file = Path(path)
    try:
        stat = file.stat()
    except OSError as exc:
        raise SourceError(f"{file.name}: the DEM cannot be read on this worker ({exc.strerror})") from exc
    if (stat.st_size, stat.st_mtime_ns) != tuple(expected):
        raise SourceError(f"{file.name}: the DEM changed while it was being traced")
    grid = read_dem(file)
    level_parts = _level_parts(grid, np.asarray(levels, dtype=np.float64), file.name)
    return [check_batch(batch, grid.crs) for parts in level_parts for batch in in_batches(parts)]


def _level_parts(grid: DemGrid, levels: NDArray[np.float64], where: str) -> Iterator[LineParts]:
    """Each of ``levels`` that has a line in ``grid``, traced when it is read and mapped to the grid's CRS."""
    for level in iter_levels(grid.z, levels):
        yield line_parts_from_traced([level], grid.transform, where)


def line_parts_from_traced(
    traced: list[LevelLines], transform: tuple[float, float, float, float, float, float], where: str
) -> LineParts:
    """Map traced lines to the grid's CRS, ids ``"{elevation}:{k}"``, node artefacts dropped and reported.

    Traced in grid index space, then mapped by the geotransform in one step: this handles north-up,
    south-up and rotated grids alike.
    """
    pieces = [line for _, lines in traced for line in lines]
    uv = np.vstack(pieces)
    counts_all = np.array([len(line) for line in pieces], dtype=np.int64)
    ids: list[FeatureId] = []
    elevations: list[float] = []
    for level, lines in traced:
        label = f"{level:.10g}"
        ids.extend(f"{label}:{k}" for k in range(len(lines)))
        elevations.extend([level] * len(lines))
    uv, counts_all, ids, elevations, bad = _drop_node_artefacts(uv, counts_all, ids, elevations, where)
    uv, counts_all = _close_touching_rings(uv, counts_all)
    xy = pixel_centres_to_crs(uv, transform)
    return LineParts(
        xy=xy,
        offsets=np.concatenate([[0], np.cumsum(counts_all)]).astype(np.int64),
        ids=ids,
        elevations=np.asarray(elevations, dtype=np.float64),
        bad=bad,
    )


def pixel_centres_to_crs(
    uv: NDArray[np.float64], transform: tuple[float, float, float, float, float, float]
) -> NDArray[np.float64]:
    """(N, 2) points given in pixel-centre grid units (column, row: node (r, k) at (k, r)) placed in the grid's
    CRS by its geotransform (:class:`DemGrid`); pixel centres sit half a pixel inside the pixel edges."""
    u, v = uv[:, 0] + 0.5, uv[:, 1] + 0.5
    a, b, c, d, e, f = transform
    return np.column_stack([a * u + b * v + c, d * u + e * v + f])


def _drop_node_artefacts(
    uv: NDArray[np.float64],
    counts: NDArray[np.int64],
    ids: list[FeatureId],
    elevations: list[float],
    where: str,
) -> tuple[NDArray[np.float64], NDArray[np.int64], list[FeatureId], list[float], list[BadFeature]]:
    """Remove lines that hug grid nodes (see :data:`NODE_SNAP_PX`); they are reported, not kept.

    ``uv`` are (N, 2) vertices in grid index space (column, row of pixel centres), ``counts`` the vertices
    per line.
    """
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    off_node = np.abs(uv - np.round(uv)).max(axis=1)  # contourpy's vertices lie on grid edges
    farthest = np.maximum.reduceat(off_node, starts)
    artefact = farthest < NODE_SNAP_PX + NODE_SNAP_SLACK_PX
    if not artefact.any():
        return uv, counts, ids, elevations, []
    bad = [
        BadFeature(
            ids[k],
            f"degenerate contour: grid nodes lie exactly at {elevations[k]:.10g}, so the line only "
            f"circles them within {NODE_SNAP_PX:g} pixel",
            where,
        )
        for k in np.flatnonzero(artefact)
    ]
    keep_line = ~artefact
    keep_vertex = np.repeat(keep_line, counts)
    ids = [ids[k] for k in np.flatnonzero(keep_line)]
    elevations = [elevations[k] for k in np.flatnonzero(keep_line)]
    return uv[keep_vertex], counts[keep_line], ids, elevations, bad


def _close_touching_rings(
    uv: NDArray[np.float64], counts: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Close open lines whose ends lie within :data:`NODE_SNAP_PX` of each other (repeat the first vertex).

    Such a line is a ring touching the data's edge at a node exactly at the level; tracing 1 mm above the
    level leaves a gap of a few centimetres that would otherwise decide, after any rounding, whether it is
    a ring.
    """
    if len(counts) == 0:
        return uv, counts
    ends = np.cumsum(counts)
    starts = ends - counts
    gap = np.hypot(*(uv[ends - 1] - uv[starts]).T)
    touching = (gap > 0) & (gap < NODE_SNAP_PX + NODE_SNAP_SLACK_PX) & (counts >= 3)
    if not touching.any():
        return uv, counts
    uv = np.insert(uv, ends[touching], uv[starts[touching]], axis=0)
    return uv, counts + touching.astype(np.int64)


def dem_vertical_units(path: str | os.PathLike[str]) -> str | None:
    """The vertical unit of a DEM from its metadata ("m" or "ft"), or None when it says none.

    The band's unit (GDAL's ``units``) wins; otherwise the axis unit of the vertical part of a compound CRS.
    An ``.npz`` grid has no metadata: None.

    Raises
    ------
    SourceError
        The raster cannot be read.
    """
    path = Path(path)
    if path.suffix.lower() in NPZ_SUFFIXES:
        return None
    header = read_header(path)
    band_unit = (header.band_unit or "").strip().lower()
    if band_unit in UNIT_NAMES:
        return UNIT_NAMES[band_unit]
    crs = pyproj.CRS.from_wkt(header.crs_wkt)
    vertical = [c for c in crs.sub_crs_list if c.is_vertical] if crs.is_compound else []
    if vertical and vertical[0].axis_info:
        return UNIT_NAMES.get(vertical[0].axis_info[0].unit_name.strip().lower())
    return None


def dem_uphill_side(path: str | os.PathLike[str]) -> str:
    """The side ("left" or "right") every contour traced from the DEM at ``path`` has higher ground on
    (:func:`~engine.io.dem_tracing.uphill_side` of its geotransform; an ``.npz`` grid's is known once read).

    Raises
    ------
    SourceError
        The DEM cannot be read.
    """
    path = Path(path)
    npz = path.suffix.lower() in NPZ_SUFFIXES
    return uphill_side(read_dem(path).transform if npz else read_header(path).transform)


#: The geotransform's turning sense of every terrain tile mosaic: Web Mercator, north up, rows running south
#: (:meth:`~engine.io.terrain_tiles.TileMosaic.header`); the pixel size does not change the side.
TILE_MOSAIC_AXES = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0)


def source_uphill_side(source: str | os.PathLike[str] | RasterDem | TerrainTiles) -> str | None:
    """The side ("left" or "right") every contour traced from a DEM source has higher ground on: a DEM file,
    a raster read in windows (a GeoTIFF URL or an area of a file: its header's geotransform, the one the
    windows are traced on) or a tile pyramid (always north up); None for a source that is not a DEM.

    Raises
    ------
    SourceError
        The DEM cannot be read.
    """
    if isinstance(source, TerrainTiles):
        return uphill_side(TILE_MOSAIC_AXES)
    if isinstance(source, RasterDem):
        return uphill_side(source.header().transform)
    if Path(source).suffix.lower() in DEM_SUFFIXES:
        return dem_uphill_side(source)
    return None
