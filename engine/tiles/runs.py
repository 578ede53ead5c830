"""Runs of rows: per-line chunk boxes (a line's own spatial index), and slicing, thinning and quantising the
runs of rows a tile meets in one compiled pass.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.types import Bounds

#: Rows per chunk of a line's own spatial index: a tile touching a long contour slices only the chunks it
#: meets, so the work per tile follows what the tile shows, not the length of the contours it touches.
CHUNK_ROWS = 32


def chunk_bounds(rows: Sequence[NDArray[np.float64]], size: int = CHUNK_ROWS) -> NDArray[np.float64]:
    """(C, 4) (minx, miny, maxx, maxy) of each chunk of rows [c*size, (c+1)*size] over several (M, 2) arrays.

    Consecutive chunks share one row, so a run of chunks is a connected piece of the line. With the CCS's
    ``base`` and ``top`` rows as input, every slice at any t lies inside the boxes (a slice point is a convex
    combination of the two rows' points).
    """
    m = len(rows[0])
    starts = np.arange(0, max(m - 1, 1), size)
    nxt = np.minimum(starts + size, m - 1)
    lo = np.full((len(starts), 2), np.inf)
    hi = np.full((len(starts), 2), -np.inf)
    for r in rows:
        lo = np.minimum(lo, np.minimum(np.minimum.reduceat(r, starts, axis=0), r[nxt]))
        hi = np.maximum(hi, np.maximum(np.maximum.reduceat(r, starts, axis=0), r[nxt]))
    return np.column_stack([lo, hi])


def chunk_bounds_packed(
    rows: Sequence[NDArray[np.float64]], off: NDArray[np.int64], size: int = CHUNK_ROWS
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """:func:`chunk_bounds` of many lines concatenated (line i is rows [off[i], off[i + 1])) in one pass.

    Returns the (C, 4) boxes of all lines' chunks, line by line, and the (n + 1,) chunk offsets per line.
    """
    m = np.diff(off)
    counts = (np.maximum(m - 1, 1) + size - 1) // size
    chunk_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    line = np.repeat(np.arange(len(m)), counts)
    local = np.arange(int(chunk_off[-1]), dtype=np.int64) - chunk_off[line]
    starts = off[line] + local * size
    nxt = np.minimum(starts + size, off[line + 1] - 1)
    lo = np.full((len(starts), 2), np.inf)
    hi = np.full((len(starts), 2), -np.inf)
    for r in rows:
        lo = np.minimum(lo, np.minimum(np.minimum.reduceat(r, starts, axis=0), r[nxt]))
        hi = np.maximum(hi, np.maximum(np.maximum.reduceat(r, starts, axis=0), r[nxt]))
    return np.column_stack([lo, hi]), chunk_off


def collinear_free(rows: NDArray[np.float64], rel_tol: float = 1e-9) -> NDArray[np.intp]:
    """Indices of the rows of a polyline that are not inside a straight run (both ends always kept)."""
    if len(rows) <= 2:
        return np.arange(len(rows))
    d = np.diff(rows, axis=0)
    a, b = d[:-1], d[1:]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = (a * b).sum(axis=1)
    scale = np.hypot(*a.T) * np.hypot(*b.T)
    turn = (np.abs(cross) > rel_tol * scale) | (dot <= 0)
    return np.concatenate([[0], np.flatnonzero(turn) + 1, [len(rows) - 1]])


def ranges(starts: NDArray[np.int64], ends: NDArray[np.int64]) -> NDArray[np.int64]:
    """The concatenation of ``arange(s, e)`` for every pair, in one pass.

    >>> ranges(np.array([2, 10]), np.array([4, 13])).tolist()
    [2, 3, 10, 11, 12]
    """
    lens = ends - starts
    total = int(lens.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    return np.arange(total, dtype=np.int64) + np.repeat(starts - (np.cumsum(lens) - lens), lens)


@njit(cache=True)
def _slice_runs_kernel(
    a, b, run_t, col, refill, sig, base, top, min_sig, x0, y0, k, out, plen, box
):  # pragma: no cover - compiled
    n = 0
    for r in range(len(a)):
        start = n
        t = run_t[r]
        c = col[r]
        full = False
        while True:
            n = start
            lx = np.int64(0)
            ly = np.int64(0)
            last = b[r] - 1
            for i in range(a[r], b[r]):
                if not full and i != a[r] and i != last and not sig[i, c] > min_sig:
                    continue
                if t >= 1.0:
                    x = top[i, 0]
                    y = top[i, 1]
                elif t <= 0.0:
                    x = base[i, 0]
                    y = base[i, 1]
                else:
                    x = base[i, 0] + t * (top[i, 0] - base[i, 0])
                    y = base[i, 1] + t * (top[i, 1] - base[i, 1])
                qx = np.int64(np.rint((x - x0) * k))
                qy = np.int64(np.rint((y0 - y) * k))
                if n > start and qx == lx and qy == ly:
                    continue
                out[n, 0] = qx
                out[n, 1] = qy
                lx = qx
                ly = qy
                n += 1
            if not full and refill[r] and n - start < 2 and b[r] - a[r] > 2:
                full = True
                continue
            break
        plen[r] = n - start
        mnx = out[start, 0]
        mxx = mnx
        mny = out[start, 1]
        mxy = mny
        for j in range(start + 1, n):
            mnx = min(mnx, out[j, 0])
            mxx = max(mxx, out[j, 0])
            mny = min(mny, out[j, 1])
            mxy = max(mxy, out[j, 1])
        box[r, 0] = mnx
        box[r, 1] = mny
        box[r, 2] = mxx
        box[r, 3] = mxy
    return n


def slice_runs(
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    run_t: NDArray[np.float64],
    col: NDArray[np.int64],
    refill: NDArray[np.bool_],
    sig: NDArray[np.float32],
    base: NDArray[np.float64],
    top: NDArray[np.float64],
    min_sig: float,
    bounds: Bounds,
    extent: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Slice, quantise and de-duplicate runs of rows in one compiled pass.

    Run ``r`` covers rows [a[r], b[r]) of ``base``/``top`` (``(M, 2)`` EPSG:3857): a row is taken when it is
    the run's first or last or its significance ``sig[row, col[r]]`` exceeds ``min_sig``; it is sliced at
    ``run_t[r]`` (``(1 - t) base + t top``, exactly ``base`` at t <= 0 and ``top`` at t >= 1), quantised as
    :func:`quantize` does and dropped when it lands on the previous point. A run marked ``refill`` that
    collapses to one point is redone with all its rows (a line smaller than a grid cell shows as the full
    line does).

    Returns
    -------
    (q, plen, box)
        The points of all runs concatenated, the number of each run's points, and each run's (minx, miny,
        maxx, maxy) in grid units.
    """
    total = int((b - a).sum())
    out = np.empty((max(total, 1), 2), dtype=np.int64)
    plen = np.empty(len(a), dtype=np.int64)
    box = np.empty((len(a), 4), dtype=np.int64)
    k = extent / (bounds.maxx - bounds.minx)
    n = _slice_runs_kernel(
        np.ascontiguousarray(a, dtype=np.int64),
        np.ascontiguousarray(b, dtype=np.int64),
        np.ascontiguousarray(run_t, dtype=np.float64),
        np.ascontiguousarray(col, dtype=np.int64),
        np.ascontiguousarray(refill, dtype=np.bool_),
        sig,
        base,
        top,
        float(min_sig),
        float(bounds.minx),
        float(bounds.maxy),
        float(k),
        out,
        plen,
        box,
    )
    return out[:n], plen, box
