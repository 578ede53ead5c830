"""Runs of rows: per-line chunk boxes (a line's own spatial index), and slicing, thinning and quantising the
runs of rows a tile meets in one compiled pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

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
    """:func:`chunk_bounds` of many lines concatenated (line i is rows [off[i], off[i + 1])) in one compiled pass
    over one or two (M, 2) arrays (a NaN row makes its chunk's box NaN, as ``np.minimum`` does: it meets nothing).

    Returns the (C, 4) boxes of all lines' chunks, line by line, and the (n + 1,) chunk offsets per line.
    """
    off = np.asarray(off, dtype=np.int64)
    m = np.diff(off)
    counts = (np.maximum(m - 1, 1) + size - 1) // size
    chunk_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    base = np.ascontiguousarray(rows[0], dtype=np.float64)
    top = np.ascontiguousarray(rows[-1], dtype=np.float64)
    boxes = np.empty((int(chunk_off[-1]), 4))
    _chunk_boxes_kernel(base, top, len(rows) > 1, off, chunk_off, size, boxes)
    return boxes, chunk_off


@njit(cache=True)
def _chunk_boxes_kernel(base, top, both, off, chunk_off, size, boxes):  # pragma: no cover - compiled
    """Chunk c of line i covers rows ``off[i] + j * size`` to ``size`` rows on, both included (j its place in
    the line), cut at the line's last row. A NaN coordinate makes that axis of its chunk's box NaN, as
    ``np.minimum`` / ``np.maximum`` do."""
    for i in range(len(off) - 1):
        for c in range(chunk_off[i], chunk_off[i + 1]):
            first = off[i] + (c - chunk_off[i]) * size
            last = min(first + size, off[i + 1] - 1)
            lox, loy, hix, hiy = np.inf, np.inf, -np.inf, -np.inf
            nan_x, nan_y = False, False
            for r in range(first, last + 1):
                x, y = base[r, 0], base[r, 1]
                lox, hix, loy, hiy = min(lox, x), max(hix, x), min(loy, y), max(hiy, y)
                nan_x, nan_y = nan_x | (x != x), nan_y | (y != y)
                if both:
                    x, y = top[r, 0], top[r, 1]
                    lox, hix, loy, hiy = min(lox, x), max(hix, x), min(loy, y), max(hiy, y)
                    nan_x, nan_y = nan_x | (x != x), nan_y | (y != y)
            if nan_x:
                lox = hix = np.nan
            if nan_y:
                loy = hiy = np.nan
            boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3] = lox, loy, hix, hiy


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
def _quantised_at(base, top, i, t, x0, y0, k):  # pragma: no cover - compiled
    if t >= 1.0:
        x = top[i, 0]
        y = top[i, 1]
    elif t <= 0.0:
        x = base[i, 0]
        y = base[i, 1]
    else:
        x = base[i, 0] + t * (top[i, 0] - base[i, 0])
        y = base[i, 1] + t * (top[i, 1] - base[i, 1])
    return np.int64(np.rint((x - x0) * k)), np.int64(np.rint((y0 - y) * k))


@njit(cache=True)
def _slice_runs_kernel(
    a, b, col, refill, run_t, sig, base, top, min_sig, x0, y0, k, out, plen, box
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
                qx, qy = _quantised_at(base, top, i, t, x0, y0, k)
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


class RowSource(Protocol):
    """The rows runs are cut from: (M, 2) EPSG:3857 ``base`` and ``top`` (a slice at t lies between them) and
    their (M, k) float32 significance ``sig``, one column per way of thinning."""

    @property
    def base(self) -> NDArray[np.float64]: ...  # noqa: D102 - described by the class

    @property
    def top(self) -> NDArray[np.float64]: ...  # noqa: D102

    @property
    def sig(self) -> NDArray[np.float32]: ...  # noqa: D102


@dataclass(frozen=True)
class RunSet:
    """Runs of rows of a :class:`RowSource`: run ``r`` covers rows [a[r], b[r]), is thinned by column ``col[r]`` of
    the significance, and is redone with all its rows when ``refill[r]`` and it collapses to one point."""

    a: NDArray[np.int64]
    b: NDArray[np.int64]
    col: NDArray[np.int64]
    refill: NDArray[np.bool_]

    @property
    def lengths(self) -> NDArray[np.int64]:
        """Rows of each run."""
        return np.asarray(self.b - self.a, dtype=np.int64)

    def kernel_args(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        """The runs as the run kernels take them first, in the dtypes they are compiled for."""
        return (
            np.ascontiguousarray(self.a, dtype=np.int64),
            np.ascontiguousarray(self.b, dtype=np.int64),
            np.ascontiguousarray(self.col, dtype=np.int64),
            np.ascontiguousarray(self.refill, dtype=np.bool_),
        )


def _rows_args(
    rows: RowSource, min_sig: float, bounds: Bounds, extent: int
) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float64], float, float, float, float]:
    """The rows, the significance threshold and the grid (origin x, origin y, units per metre) as the run
    kernels take them, after the runs' t."""
    k = extent / (bounds.maxx - bounds.minx)
    return rows.sig, rows.base, rows.top, float(min_sig), float(bounds.minx), float(bounds.maxy), float(k)


def _float64(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """A t array as the run kernels are compiled for it."""
    return np.ascontiguousarray(t, dtype=np.float64)


def slice_runs(
    runs: RunSet,
    run_t: NDArray[np.float64],
    rows: RowSource,
    min_sig: float,
    bounds: Bounds,
    extent: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Slice, quantise and de-duplicate runs of rows in one compiled pass.

    A row of a run is taken when it is the run's first or last or its significance ``rows.sig[row, col[r]]``
    exceeds ``min_sig``; it is sliced at ``run_t[r]`` (``(1 - t) base +
    t top``, exactly ``base`` at t <= 0 and ``top`` at t >= 1), quantised as :func:`quantize` does and dropped
    when it lands on the previous point. A run marked ``refill`` that collapses to one point is redone with all
    its rows (a line smaller than a grid cell shows as the full line does).

    Returns
    -------
    (q, plen, box)
        The points of all runs concatenated, the number of each run's points, and each run's (minx, miny,
        maxx, maxy) in grid units.
    """
    total = int(runs.lengths.sum())
    out = np.empty((max(total, 1), 2), dtype=np.int64)
    plen = np.empty(len(runs.a), dtype=np.int64)
    box = np.empty((len(runs.a), 4), dtype=np.int64)
    n = _slice_runs_kernel(
        *runs.kernel_args(), _float64(run_t), *_rows_args(rows, min_sig, bounds, extent), out, plen, box
    )
    return out[:n], plen, box


def slice_runs_exact(
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    run_t: NDArray[np.float64],
    rows: RowSource,
    bounds: Bounds,
    extent: int,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Every row of the runs sliced at ``run_t`` (as :func:`slice_runs` slices them), in float grid units, y
    down, with no row left out and nothing rounded: the exact lines that snap rounding starts from.

    Returns
    -------
    (pts, plen)
        (N, 2) float64 points of all runs concatenated and each run's number of points.
    """
    base, top = rows.base, rows.top
    taken = ranges(a, b)
    t = np.repeat(np.asarray(run_t, dtype=np.float64), b - a)[:, None]
    xy = np.where(t >= 1.0, top[taken], np.where(t <= 0.0, base[taken], base[taken] + t * (top[taken] - base[taken])))
    k = extent / (bounds.maxx - bounds.minx)
    pts = np.column_stack([(xy[:, 0] - bounds.minx) * k, (bounds.maxy - xy[:, 1]) * k])
    return pts, (b - a).astype(np.int64)


@njit(cache=True)
def _segment_reaches(s0, s1, j, lo, hi):  # pragma: no cover - compiled
    # The segment's path through the level lies in the box of its two ends at both zooms.
    mnx = min(min(s0[j, 0], s0[j + 1, 0]), min(s1[j, 0], s1[j + 1, 0]))
    mxx = max(max(s0[j, 0], s0[j + 1, 0]), max(s1[j, 0], s1[j + 1, 0]))
    mny = min(min(s0[j, 1], s0[j + 1, 1]), min(s1[j, 1], s1[j + 1, 1]))
    mxy = max(max(s0[j, 1], s0[j + 1, 1]), max(s1[j, 1], s1[j + 1, 1]))
    return mxx >= lo and mnx <= hi and mxy >= lo and mny <= hi


@njit(cache=True)
def _morph_runs_kernel(
    a, b, col, refill, t0, t1, sig, base, top, min_sig, x0, y0, k, lo, hi, q0, q1, plen, prun, s0, s1
):  # noqa: C901  # pragma: no cover - compiled, one loop nest
    n = 0
    p = 0
    for r in range(len(a)):
        c = col[r]
        full = False
        while True:
            m = 0
            last = b[r] - 1
            for i in range(a[r], b[r]):
                if not full and i != a[r] and i != last and not sig[i, c] > min_sig:
                    continue
                ax, ay = _quantised_at(base, top, i, t0[r], x0, y0, k)
                bx, by = _quantised_at(base, top, i, t1[r], x0, y0, k)
                if m > 0 and ax == s0[m - 1, 0] and ay == s0[m - 1, 1] and bx == s1[m - 1, 0] and by == s1[m - 1, 1]:
                    continue
                s0[m, 0] = ax
                s0[m, 1] = ay
                s1[m, 0] = bx
                s1[m, 1] = by
                m += 1
            if not full and refill[r] and m < 2 and b[r] - a[r] > 2:
                full = True
                continue
            break
        j = 0
        while j < m - 1:
            if not _segment_reaches(s0, s1, j, lo, hi):
                j += 1
                continue
            start = n
            q0[n, 0] = s0[j, 0]
            q0[n, 1] = s0[j, 1]
            q1[n, 0] = s1[j, 0]
            q1[n, 1] = s1[j, 1]
            n += 1
            while j < m - 1 and _segment_reaches(s0, s1, j, lo, hi):
                q0[n, 0] = s0[j + 1, 0]
                q0[n, 1] = s0[j + 1, 1]
                q1[n, 0] = s1[j + 1, 0]
                q1[n, 1] = s1[j + 1, 1]
                n += 1
                j += 1
            plen[p] = n - start
            prun[p] = r
            p += 1
    return n, p


def morph_runs(
    runs: RunSet,
    t_start: NDArray[np.float64],
    t_end: NDArray[np.float64],
    rows: RowSource,
    min_sig: float,
    bounds: Bounds,
    extent: int,
    buffer_px: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Runs of rows sliced at two t with the same vertices: the two ends of a zoom level of a morph tile.

    Rows are chosen once for both ends (as :func:`slice_runs` chooses them); a row is dropped only when it
    lands on the previous kept row at both ends. Instead of clipping (the cut point would move with t), a
    run keeps the segments whose path through the level can reach the buffered tile (the box of the
    segment's ends at both t meets it) and is split into parts where it cannot.

    Returns
    -------
    (q_start, q_end, part_len, part_run)
        The parts' points at ``t_start`` and at ``t_end`` (same shape), each part's number of points (>= 2)
        and the run each part comes from (parts in run order).
    """
    total = int(runs.lengths.sum())
    longest = int(runs.lengths.max()) if len(runs.a) else 0
    q0 = np.empty((max(total, 1), 2), dtype=np.int64)
    q1 = np.empty_like(q0)
    plen = np.empty(max(total, 1), dtype=np.int64)
    prun = np.empty(max(total, 1), dtype=np.int64)
    s0 = np.empty((max(longest, 1), 2), dtype=np.int64)
    s1 = np.empty_like(s0)
    n, p = _morph_runs_kernel(
        *runs.kernel_args(),
        _float64(t_start),
        _float64(t_end),
        *_rows_args(rows, min_sig, bounds, extent),
        -buffer_px,
        extent + buffer_px,
        q0,
        q1,
        plen,
        prun,
        s0,
        s1,
    )
    return q0[:n], q1[:n], plen[:p], prun[:p]
