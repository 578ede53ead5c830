"""Does a tile's integer drawing have two different lines crossing properly? One compiled pass.

A proper crossing is two segments meeting at a point inside both (touching, shared vertices and overlapping
runs are not; ``engine.ccsm.topology.lines_cross_properly`` is the same predicate on floats). The renderer asks
this of every tile after plain rounding and snap-rounds only the tiles where the answer is yes
(docs/design.md section 4.8). Segments are put into the cells of a coarse grid they pass through, and only
segments sharing a cell are compared, with exact integer orientation tests. The grid has about as many cells as
the drawing has segments (cells of at least :data:`MIN_CELL_UNITS`): a fixed fine grid over the whole buffered
tile cost more to clear and walk than the comparisons it saved.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Fewest grid units per side of a cell of the coarse grid: a few segments per cell on the densest tiles.
MIN_CELL_UNITS = 8


@njit(cache=True, nogil=True, inline="always")
def orientation_sign(ax, ay, bx, by, cx, cy):  # pragma: no cover - compiled
    """Sign of the turn a -> b -> c: 1 left, -1 right, 0 on one line (integer or float points)."""
    d = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (d > 0) - (d < 0)


@njit(cache=True)
def _cells_of_segment(px, py, qx, qy, lo, size, cell, cells):  # pragma: no cover - compiled
    """The coarse cells (row-major indices, ``cell`` units a side) the segment p -> q passes through; returns
    how many."""
    ux, uy = (px - lo) / cell, (py - lo) / cell
    vx, vy = (qx - lo) / cell, (qy - lo) / cell
    cx, cy = np.int64(np.floor(ux)), np.int64(np.floor(uy))
    ex, ey = np.int64(np.floor(vx)), np.int64(np.floor(vy))
    dx, dy = vx - ux, vy - uy
    sx = np.int64(1) if dx > 0 else np.int64(-1)
    sy = np.int64(1) if dy > 0 else np.int64(-1)
    tx = ((cx + 1 - ux) / dx if dx > 0 else (ux - cx) / -dx) if dx != 0 else np.inf
    ty = ((cy + 1 - uy) / dy if dy > 0 else (uy - cy) / -dy) if dy != 0 else np.inf
    stx = abs(1.0 / dx) if dx != 0 else np.inf
    sty = abs(1.0 / dy) if dy != 0 else np.inf
    k = 0
    cells[k] = cy * size + cx
    k += 1
    while cx != ex or cy != ey:
        # Step along both axes at a corner, and add both side cells: conservative, never misses a cell.
        if cy == ey or (cx != ex and tx <= ty):
            if cx != ex and cy != ey and tx == ty:
                cells[k] = (cy + sy) * size + cx
                k += 1
            cx += sx
            tx += stx
        else:
            cy += sy
            ty += sty
        cells[k] = cy * size + cx
        k += 1
    return k


@njit(cache=True)
def _segments_in_cells(pts, part_len, part_owner, lo, size, cell):  # pragma: no cover - compiled
    """Every segment (each point but the last of each part: segment s runs from point seg_start[s] to the next)
    with its owner, and the segments of each cell: ``members[offsets[g]:offsets[g + 1]]``. Each segment's cells
    are walked once, kept, then counted into place."""
    n_seg = 0
    for p in range(len(part_len)):
        n_seg += part_len[p] - 1
    seg_start = np.empty(n_seg, dtype=np.int64)
    seg_owner = np.empty(n_seg, dtype=np.int64)
    bound = 0
    s = 0
    i = 0
    for p in range(len(part_len)):
        for j in range(i, i + part_len[p] - 1):
            seg_start[s] = j
            seg_owner[s] = part_owner[p]
            span = abs(pts[j + 1, 0] - pts[j, 0]) + abs(pts[j + 1, 1] - pts[j, 1])
            bound += 2 * (span // cell + 4) + 4  # room for any segment's cells, as _cells_of_segment walks them
            s += 1
        i += part_len[p]
    walked = np.empty(bound, dtype=np.int64)
    seg_cells = np.empty(n_seg + 1, dtype=np.int64)
    counts = np.zeros(size * size + 1, dtype=np.int64)
    w = 0
    for s in range(n_seg):
        j = seg_start[s]
        seg_cells[s] = w
        k = _cells_of_segment(pts[j, 0], pts[j, 1], pts[j + 1, 0], pts[j + 1, 1], lo, size, cell, walked[w:])
        for c in range(w, w + k):
            counts[walked[c] + 1] += 1
        w += k
    seg_cells[n_seg] = w
    offsets = np.cumsum(counts)
    fill = offsets.copy()
    members = np.empty(w, dtype=np.int64)
    for s in range(n_seg):
        for c in range(seg_cells[s], seg_cells[s + 1]):
            members[fill[walked[c]]] = s
            fill[walked[c]] += 1
    return seg_start, seg_owner, offsets, members


@njit(cache=True)
def _crossing_kernel(pts, part_len, part_owner, lo, size, cell, first_only, found):  # pragma: no cover - compiled
    seg_start, seg_owner, offsets, members = _segments_in_cells(pts, part_len, part_owner, lo, size, cell)
    n_found = 0
    for g in range(size * size):
        for u in range(offsets[g], offsets[g + 1]):
            a = seg_start[members[u]]
            for v in range(u + 1, offsets[g + 1]):
                if seg_owner[members[u]] == seg_owner[members[v]]:
                    continue
                b = seg_start[members[v]]
                o1 = orientation_sign(pts[a, 0], pts[a, 1], pts[a + 1, 0], pts[a + 1, 1], pts[b, 0], pts[b, 1])
                o2 = orientation_sign(pts[a, 0], pts[a, 1], pts[a + 1, 0], pts[a + 1, 1], pts[b + 1, 0], pts[b + 1, 1])
                if o1 * o2 >= 0:
                    continue
                o3 = orientation_sign(pts[b, 0], pts[b, 1], pts[b + 1, 0], pts[b + 1, 1], pts[a, 0], pts[a, 1])
                o4 = orientation_sign(pts[b, 0], pts[b, 1], pts[b + 1, 0], pts[b + 1, 1], pts[a + 1, 0], pts[a + 1, 1])
                if o3 * o4 < 0:
                    if n_found < len(found):
                        found[n_found, 0] = seg_owner[members[u]]
                        found[n_found, 1] = seg_owner[members[v]]
                    n_found += 1
                    if first_only:
                        return n_found
    return n_found


def _segments(
    pts: NDArray[np.int64], part_len: NDArray[np.int64], part_owner: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], int, int, int]:
    """Points, length and owner of each part, and the coarse grid (origin, cells a side, units a cell)."""
    pts = np.ascontiguousarray(pts, dtype=np.int64)
    lens = np.ascontiguousarray(part_len, dtype=np.int64)
    lo = int(pts.min()) - 1
    span = int(pts.max()) - lo
    # About one cell per segment: the grid's cost follows the drawing, not the tile's area.
    cell = max(MIN_CELL_UNITS, int(span / np.sqrt(max(len(pts) - len(lens), 1))))
    size = span // cell + 2
    return pts, lens, np.ascontiguousarray(part_owner, dtype=np.int64), lo, size, cell


def lines_cross_in_grid(pts: NDArray[np.int64], part_len: NDArray[np.int64], part_owner: NDArray[np.int64]) -> bool:
    """Whether a segment of one line crosses a segment of a different line properly.

    Parameters
    ----------
    pts
        (N, 2) int64 grid points of every part, concatenated.
    part_len
        (P,) points of each part (each >= 2).
    part_owner
        (P,) the line (feature) each part belongs to; parts of one line are never compared.

    >>> x = np.array([[0, 0], [4, 4], [0, 4], [4, 0]])
    >>> lines_cross_in_grid(x, np.array([2, 2]), np.array([0, 1]))
    True
    >>> lines_cross_in_grid(x, np.array([2, 2]), np.array([0, 0]))  # one line crossing itself: not counted
    False
    >>> t = np.array([[0, 0], [4, 0], [2, 0], [2, 3]])
    >>> lines_cross_in_grid(t, np.array([2, 2]), np.array([0, 1]))  # a T: touching only
    False
    """
    if len(part_len) < 2:
        return False
    found = np.zeros((1, 2), dtype=np.int64)
    return bool(_crossing_kernel(*_segments(pts, part_len, part_owner), True, found))


def crossing_owner_pairs(
    pts: NDArray[np.int64], part_len: NDArray[np.int64], part_owner: NDArray[np.int64]
) -> set[tuple[int, int]]:
    """The pairs (a, b), a < b, of owners with a segment of one crossing a segment of the other properly.

    >>> x = np.array([[0, 0], [4, 4], [0, 4], [4, 0], [9, 9], [9, 12]])
    >>> crossing_owner_pairs(x, np.array([2, 2, 2]), np.array([5, 3, 1]))
    {(3, 5)}
    """
    if len(part_len) < 2:
        return set()
    found = np.zeros((64, 2), dtype=np.int64)
    args = _segments(pts, part_len, part_owner)
    n = _crossing_kernel(*args, False, found)
    if n > len(found):  # more than the first guess: run again with room for all
        found = np.zeros((n, 2), dtype=np.int64)
        _crossing_kernel(*args, False, found)
    pairs = np.sort(found[:n], axis=1)
    return {(int(a), int(b)) for a, b in pairs.tolist()}
