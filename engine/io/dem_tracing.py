"""Contour levels of a height range and their lines, traced by contourpy: the step a whole DEM
(:mod:`engine.io.dem`) and each window of a large one (:mod:`engine.io.dem_windows`) share."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import contourpy
import numpy as np
from numpy.typing import NDArray

from engine.errors import InvalidParameter

#: Contours are traced this far (in the DEM's vertical unit, metres in practice) above their nominal level.
#: DEMs with whole-metre heights put grid nodes exactly on multiples of the interval; tracing there makes
#: repeated vertices and zero-length pieces (docs/design.md section 6). A millimetre is far below any DEM's
#: accuracy.
LEVEL_OFFSET = 1e-3

#: More levels than this means the interval is wrong for the data (a 0.01 m interval on a mountain range).
MAX_LEVELS = 5000


def contour_levels(zmin: float, zmax: float, interval: float) -> NDArray[np.float64]:
    """Nominal levels: every multiple of ``interval`` within [zmin, zmax].

    >>> contour_levels(236.0, 1076.0, 20.0)[[0, -1]].tolist()
    [240.0, 1060.0]
    """
    first = math.ceil(zmin / interval)
    last = math.floor(zmax / interval)
    if last - first + 1 > MAX_LEVELS:
        raise InvalidParameter(
            f"interval {interval} gives {last - first + 1} levels over [{zmin}, {zmax}] (more than {MAX_LEVELS})",
            parameter="interval",
        )
    # Rounding keeps 0.1 · 3 at 0.3, so elevations and ids read as the user typed the interval.
    return np.round(np.arange(first, last + 1, dtype=np.float64) * interval, 9)


def uphill_side(transform: tuple[float, float, float, float, float, float]) -> str:
    """The side of its direction ("left" or "right") every line traced from a grid with this geotransform has
    higher ground on, in the grid's CRS (x east, y north).

    contourpy turns every line so that higher values lie on its left in grid index space (column, row); the
    geotransform keeps that side where it keeps the turning sense (its determinant is positive) and mirrors
    it otherwise, as a north-up grid (rows running south) does. Joins across windows and the cleaning keep
    every line's direction (docs/design.md section 4.4), so the side holds for the stored contours.

    >>> uphill_side((30.0, 0.0, 0.0, 0.0, -30.0, 0.0)), uphill_side((30.0, 0.0, 0.0, 0.0, 30.0, 0.0))
    ('right', 'left')
    """
    a, b, _, d, e, _ = transform
    return "left" if a * e - b * d > 0 else "right"


#: Lines of one level in grid index space: (level, [(n, 2) points of each line]).
LevelLines = tuple[float, list[NDArray[np.float64]]]


def iter_levels(z: np.ma.MaskedArray, levels: NDArray[np.float64]) -> Iterator[LevelLines]:
    """Lines of every level in grid index space (x = column, y = row of the pixel centre), each level traced
    when it is read, levels without a line left out; a closed ring repeats its first vertex at the end, as
    contourpy returns it."""
    generator = contourpy.contour_generator(
        z=z, name="serial", line_type=contourpy.LineType.ChunkCombinedOffset, chunk_size=0
    )
    for level in levels.tolist():
        # ChunkCombinedOffset with one chunk: ([points (n, 2)] or [None], [offsets (m + 1,)] or [None]).
        lines: Any = generator.lines(level + LEVEL_OFFSET)
        points, offsets = lines
        if not points or points[0] is None:
            continue
        pts = np.asarray(points[0], dtype=np.float64)
        off = np.asarray(offsets[0], dtype=np.int64)
        yield level, np.split(pts, off[1:-1])
