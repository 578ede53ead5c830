"""Snap rounding: lines on the integer tile grid that never cross where the exact lines do not.

Plain rounding moves every vertex to its nearest grid point on its own, so two lines closer than a grid unit
can swap sides and cross. Snap rounding (Hobby; Guibas and Marimont) rounds the whole drawing at once:

- every grid *pixel* (the half-open unit square ``[i - 1/2, i + 1/2) x [j - 1/2, j + 1/2)`` around the grid
  point ``(i, j)``) that holds a vertex of any line is *hot*;
- each segment is replaced by the path through the centres of the hot pixels it passes through, in order along
  the segment; consecutive repeats are dropped (vertices that fall into one hot pixel collapse into one).

The guarantee (Guibas and Marimont 1995): the rounded drawing is a continuous deformation of the exact one in
which no vertex ever passes through a segment. So two lines that do not meet before rounding do not cross after
it; where they were closer than a pixel they may touch or share a run of segments, which is all the grid can
show (docs/design.md section 4.8). A line stays within a pixel of itself (every output vertex is the centre of
a hot pixel the exact line passes through).

The segment-pixel walk follows the half-open convention exactly (a segment through a pixel corner enters the
pixel that owns the corner), and a vertex rounds with ``floor(v + 1/2)``, the same convention.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Marks an empty slot of the hot-pixel hash table (no pixel key is negative: keys are offset to be >= 0).
_EMPTY = np.int64(-1)
#: Offset that makes pixel coordinates non-negative in a key; tile coordinates stay far below it.
_KEY_OFFSET = np.int64(1 << 30)


@njit(cache=True, inline="always")
def _key(i, j):  # pragma: no cover - compiled
    return ((i + _KEY_OFFSET) << np.int64(32)) | (j + _KEY_OFFSET)


@njit(cache=True, inline="always")
def _slot(key, mask):  # pragma: no cover - compiled
    h = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64((h >> np.uint64(17)) & np.uint64(mask))


@njit(cache=True)
def _hot_table(pts):  # pragma: no cover - compiled
    """Open-addressing hash set of the pixel keys of every vertex (table size a power of two >= 4 N)."""
    size = 16
    while size < 4 * len(pts):
        size *= 2
    table = np.full(size, _EMPTY, dtype=np.int64)
    mask = size - 1
    for v in range(len(pts)):
        key = _key(np.int64(np.floor(pts[v, 0] + 0.5)), np.int64(np.floor(pts[v, 1] + 0.5)))
        s = _slot(key, mask)
        while table[s] != _EMPTY and table[s] != key:
            s = (s + 1) & mask
        table[s] = key
    return table


@njit(cache=True, inline="always")
def _is_hot(table, i, j):  # pragma: no cover - compiled
    key = _key(i, j)
    mask = len(table) - 1
    s = _slot(key, mask)
    while table[s] != _EMPTY:
        if table[s] == key:
            return True
        s = (s + 1) & mask
    return False


@njit(cache=True, inline="always")
def _emit(out, n, start, i, j):  # pragma: no cover - compiled
    if n > start and out[n - 1, 0] == i and out[n - 1, 1] == j:
        return n
    out[n, 0] = i
    out[n, 1] = j
    return n + 1


@njit(cache=True, inline="always")
def _first_boundary(u, c, d):  # pragma: no cover - compiled
    # Parameter along the segment at which it reaches the next pixel boundary on one axis (u in pixel c,
    # moving d along it over the whole segment), and the parameter step from one boundary to the next.
    if d > 0:
        return (c + 1 - u) / d, 1.0 / d
    if d < 0:
        return (u - c) / -d, 1.0 / -d
    return np.inf, np.inf


@njit(cache=True)
def _walk_segment(table, px, py, qx, qy, out, n, start):  # noqa: C901  # pragma: no cover - compiled
    """Emit the centres of the hot pixels the segment p -> q passes through after p's own pixel, in order."""
    ux, uy = px + 0.5, py + 0.5  # pixel (i, j) is [i, i + 1) x [j, j + 1) in these shifted coordinates
    cx, cy = np.int64(np.floor(ux)), np.int64(np.floor(uy))
    ex, ey = np.int64(np.floor(qx + 0.5)), np.int64(np.floor(qy + 0.5))
    dx, dy = qx - px, qy - py
    sx = np.int64(1) if dx > 0 else np.int64(-1)
    sy = np.int64(1) if dy > 0 else np.int64(-1)
    tx, step_x = _first_boundary(ux, cx, dx)
    ty, step_y = _first_boundary(uy, cy, dy)
    left = abs(ex - cx) + abs(ey - cy)
    while left > 0:
        if cx == ex:
            move_x, move_y = False, True
        elif cy == ey:
            move_x, move_y = True, False
        elif tx < ty:
            move_x, move_y = True, False
        elif ty < tx:
            move_x, move_y = False, True
        elif (dx > 0) == (dy > 0):
            # Through a corner that belongs to the diagonal pixel (both coordinates rising or both falling).
            move_x, move_y = True, True
        else:
            # Through a corner owned by the side pixel on the rising axis: enter it first.
            move_x, move_y = dx > 0, dy > 0
        if move_x:
            cx += sx
            tx += step_x
            left -= 1
        if move_y:
            cy += sy
            ty += step_y
            left -= 1
        if _is_hot(table, cx, cy):
            n = _emit(out, n, start, cx, cy)
    return n


@njit(cache=True)
def _snap_round_kernel(pts, part_len, out, out_len, out_src):  # pragma: no cover - compiled
    table = _hot_table(pts)
    n = 0
    m = 0
    p = 0
    for j in range(len(part_len)):
        start = n
        n = _emit(out, n, start, np.int64(np.floor(pts[p, 0] + 0.5)), np.int64(np.floor(pts[p, 1] + 0.5)))
        for i in range(p, p + part_len[j] - 1):
            n = _walk_segment(table, pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1], out, n, start)
        if n - start >= 2:
            out_len[m] = n - start
            out_src[m] = j
            m += 1
        else:
            n = start  # the whole part fell into one pixel: nothing to draw
        p += part_len[j]
    return n, m


def snap_round(
    pts: NDArray[np.float64], part_len: NDArray[np.int64], *, capacity: int | None = None
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Snap-round polylines to the integer grid, all together (see the module docstring for the guarantee).

    Parameters
    ----------
    pts
        (N, 2) float64 points of every part, concatenated, in grid units.
    part_len
        (P,) points of each part (each >= 1).
    capacity
        Room for output points; by default the sum over segments of the pixels each spans (always enough).

    Returns
    -------
    (q, lens, src)
        (M, 2) int64 grid points of the parts that keep >= 2 points, each part's point count, and the input
        part each comes from.

    >>> a = np.array([[0.0, 0.6], [4.0, 0.3]])              # a line, and a line that dips to 0.04 below it
    >>> b = np.array([[0.0, 3.0], [2.0, 0.49], [4.0, 3.0]])  # plain rounding puts the dip past the line
    >>> q, lens, src = snap_round(np.concatenate([a, b]), np.array([2, 3]))
    >>> q.tolist(), lens.tolist()                               # both run through the dip's pixel: they touch
    ([[0, 1], [2, 0], [4, 0], [0, 3], [2, 0], [4, 3]], [3, 3])
    """
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    lens = np.ascontiguousarray(part_len, dtype=np.int64)
    if len(lens) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    if capacity is None:
        d = np.abs(np.diff(np.floor(pts + 0.5), axis=0)).sum(axis=1) if len(pts) > 1 else np.zeros(0)
        capacity = int(d.sum()) + len(pts) + 1
    out = np.empty((capacity, 2), dtype=np.int64)
    out_len = np.empty(len(lens), dtype=np.int64)
    out_src = np.empty(len(lens), dtype=np.int64)
    n, m = _snap_round_kernel(pts, lens, out, out_len, out_src)
    return out[:n], out_len[:m], out_src[:m]
