"""Clipping integer polylines to the buffered tile square in one compiled Liang–Barsky pass.

The edge arithmetic follows GEOS's rectangle clipping, so the pieces equal what ``shapely.clip_by_rect`` gives
(the tests compare them).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True)
def _clip_one_edge(x1, y1, x2, y2, limit):  # pragma: no cover - compiled
    if x2 == limit:
        return x2, y2
    if x1 != x2:
        return limit, y1 + (y2 - y1) * (limit - x1) / (x2 - x1)
    return x1, y1


@njit(cache=True)
def _clip_to_edges(x1, y1, x2, y2, lo, hi):  # pragma: no cover - compiled
    # Move the outside point (x1, y1) along the segment towards (x2, y2) onto the rectangle, one edge after
    # the other, with GEOS's arithmetic (RectangleIntersection), so that rounding agrees with clip_by_rect.
    if x1 < lo:
        x1, y1 = _clip_one_edge(x1, y1, x2, y2, lo)
    elif x1 > hi:
        x1, y1 = _clip_one_edge(x1, y1, x2, y2, hi)
    if y1 < lo:
        y1, x1 = _clip_one_edge(y1, x1, y2, x2, lo)
    elif y1 > hi:
        y1, x1 = _clip_one_edge(y1, x1, y2, x2, hi)
    return x1, y1


@njit(cache=True)
def _close(n, start, j, out_len, out_src, m):  # pragma: no cover - compiled
    if n - start >= 2:
        out_len[m] = n - start
        out_src[m] = j
        return n, m + 1
    return start, m


@njit(cache=True)
def _clip_kernel(q, plen, lo, hi, out, out_len, out_src, to_grid):  # noqa: C901  # pragma: no cover - compiled, one loop nest
    n = 0
    m = 0
    s = 0
    for j in range(len(plen)):
        opened = False
        start = 0
        for i in range(s, s + plen[j] - 1):
            px = float(q[i, 0])
            py = float(q[i, 1])
            dx = float(q[i + 1, 0]) - px
            dy = float(q[i + 1, 1]) - py
            t0 = 0.0
            t1 = 1.0
            ok = True
            for e in range(4):
                if e == 0:
                    pk, qk = -dx, px - lo
                elif e == 1:
                    pk, qk = dx, hi - px
                elif e == 2:
                    pk, qk = -dy, py - lo
                else:
                    pk, qk = dy, hi - py
                if pk == 0.0:
                    if qk < 0.0:
                        ok = False
                        break
                else:
                    t = qk / pk
                    if pk < 0.0:
                        if t > t0:
                            t0 = t
                    elif t < t1:
                        t1 = t
            if ok and t0 <= t1:
                rx = px + dx
                ry = py + dy
                ax, ay = _clip_to_edges(px, py, rx, ry, lo, hi) if t0 > 0.0 else (px, py)
                bx, by = _clip_to_edges(rx, ry, px, py, lo, hi) if t1 < 1.0 else (rx, ry)
                # A part running along the rectangle's boundary is not part of the clipped line (as in GEOS).
                if (ax == bx and (ax == lo or ax == hi)) or (ay == by and (ay == lo or ay == hi)):
                    ok = False
            if not ok or t0 > t1:
                if opened:
                    n, m = _close(n, start, j, out_len, out_src, m)
                    opened = False
                continue
            if not opened or t0 > 0.0:
                if opened:
                    n, m = _close(n, start, j, out_len, out_src, m)
                start = n
                opened = True
                out[n, 0] = np.rint(ax) if to_grid else ax
                out[n, 1] = np.rint(ay) if to_grid else ay
                n += 1
            ix = np.rint(bx) if to_grid else bx
            iy = np.rint(by) if to_grid else by
            if ix != out[n - 1, 0] or iy != out[n - 1, 1]:
                out[n, 0] = ix
                out[n, 1] = iy
                n += 1
            if t1 < 1.0:
                n, m = _close(n, start, j, out_len, out_src, m)
                opened = False
        if opened:
            n, m = _close(n, start, j, out_len, out_src, m)
        s += plen[j]
    return n, m


def clip_lines_fast(
    q: NDArray[np.int64], lens: NDArray[np.int64], lo: int, hi: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`clip_lines` in one compiled Liang–Barsky pass (the same pieces; no shapely objects)."""
    return _clip(np.ascontiguousarray(q, dtype=np.int64), lens, lo, hi, to_grid=True)


def clip_lines_exact(
    q: NDArray[np.float64], lens: NDArray[np.int64], lo: float, hi: float
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`clip_lines_fast` of float polylines, keeping the cut points as they are (not rounded): the
    pieces of exact lines that snap rounding then puts on the grid (engine.tiles.snap_round)."""
    return _clip(np.ascontiguousarray(q, dtype=np.float64), lens, lo, hi, to_grid=False)


def _clip(
    q: NDArray[Any], lens: NDArray[np.int64], lo: float, hi: float, *, to_grid: bool
) -> tuple[NDArray[Any], NDArray[np.int64], NDArray[np.int64]]:
    # The kernel cuts float or integer lines alike; to_grid rounds the cut points to the grid.
    lens = np.ascontiguousarray(lens, dtype=np.int64)
    out = np.empty((2 * len(q) + 2, 2), dtype=q.dtype)
    out_len = np.empty(len(q) + 1, dtype=np.int64)
    out_src = np.empty(len(q) + 1, dtype=np.int64)
    n, m = _clip_kernel(q, lens, float(lo), float(hi), out, out_len, out_src, to_grid)
    return out[:n], out_len[:m], out_src[:m]
