"""A grid over fixed points, to find those in a rectangle without looking at every one.

A tile's label layer tests only the anchors in the grid cells its tile covers, so its cost follows the labels
near the tile, not the number of labels in the dataset (122,000 at 64× the sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.tiles.runs import ranges

#: Points per cell the grid is sized for, on average (fewer cells cost memory, more cost the query's ranges).
POINTS_PER_CELL = 8
#: Cells along each side at most.
MAX_SIDE = 1024


@dataclass(frozen=True)
class PointGrid:
    """Points sorted by the cell of a ``side`` x ``side`` grid over their extent."""

    #: x0, y0: the grid's lower left corner.
    x0: float
    y0: float
    #: cell_w, cell_h: a cell's size.
    cell_w: float
    cell_h: float
    #: Cells along each side.
    side: int
    #: Positions of the points, sorted by cell (row by row; in a cell, by position).
    order: NDArray[np.intp]
    #: (side * side + 1,) offsets of each cell's points in ``order``.
    start: NDArray[np.int64]

    @classmethod
    def of(cls, xy: NDArray[np.float64]) -> PointGrid:
        """The grid of (n, 2) points."""
        n = len(xy)
        side = max(1, min(MAX_SIDE, math.ceil(math.sqrt(n / POINTS_PER_CELL))))
        lo = xy.min(axis=0) if n else np.zeros(2)
        hi = xy.max(axis=0) if n else np.ones(2)
        # A cell of positive size even for points on a line (or one point).
        w = max(float(hi[0] - lo[0]) / side, 1e-9)
        h = max(float(hi[1] - lo[1]) / side, 1e-9)
        grid = cls(float(lo[0]), float(lo[1]), w, h, side, np.zeros(0, np.intp), np.zeros(0, np.int64))
        cx, cy = grid._cells(xy[:, 0], xy[:, 1])
        cell = cy * side + cx
        order = np.argsort(cell, kind="stable")
        start = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=side * side))]).astype(np.int64)
        return cls(grid.x0, grid.y0, w, h, side, order, start)

    def _cells(
        self, x: NDArray[np.float64] | float, y: NDArray[np.float64] | float
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Cell column and row of coordinates (those outside the grid in its border cells). Monotone in x and
        y, so the cells of a rectangle's corners bound the cells of every point inside it."""
        cx = np.clip(np.floor((np.asarray(x) - self.x0) / self.cell_w), 0, self.side - 1).astype(np.int64)
        cy = np.clip(np.floor((np.asarray(y) - self.y0) / self.cell_h), 0, self.side - 1).astype(np.int64)
        return cx, cy

    def near(self, minx: float, miny: float, maxx: float, maxy: float) -> NDArray[np.intp]:
        """Positions (ascending) of the points in the cells that meet the closed rectangle: every point inside
        it, and maybe some around it (the caller tests them exactly)."""
        (cx0, cx1), (cy0, cy1) = self._cells(np.array([minx, maxx]), np.array([miny, maxy]))
        rows = np.arange(cy0, cy1 + 1, dtype=np.int64) * self.side
        found = self.order[ranges(self.start[rows + cx0], self.start[rows + cx1 + 1])]
        return np.sort(found)
