"""Web Mercator tile math, quantisation to the tile grid and clipping (the mercantile conventions).

Tiles are XYZ (``y = 0`` at the north edge), EPSG:3857 metres. A tile's grid has ``extent`` units per side
(4096 by default), y pointing down as MVT wants it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import shapely
from numba import njit
from numpy.typing import NDArray

from engine.errors import InvalidParameter, TileOutOfRange

#: Half the width of the Web Mercator square, metres (pi x 6378137).
HALF_WORLD_M = math.pi * 6378137.0
#: Largest tile zoom any request may name (the tile matrix of z 30 already has 1e9 columns).
MAX_TILE_ZOOM = 30
#: Web Mercator's latitude limit, degrees.
MAX_LATITUDE_DEG = 85.0511287798066


class Tile(NamedTuple):
    """An XYZ tile index: zoom ``z``, column ``x`` (west to east), row ``y`` (north to south)."""

    z: int
    x: int
    y: int


class Bounds(NamedTuple):
    """(minx, miny, maxx, maxy) rectangle; units as stated where it is used (EPSG:3857 metres or degrees)."""

    minx: float
    miny: float
    maxx: float
    maxy: float


def check_tile(z: int, x: int, y: int, min_zoom: int = 0, max_zoom: int = MAX_TILE_ZOOM) -> Tile:
    """Validate a tile index against its zoom's tile matrix and the served zoom range.

    >>> check_tile(1, 1, 0)
    Tile(z=1, x=1, y=0)

    Raises
    ------
    TileOutOfRange
        ``z`` outside [min_zoom, max_zoom], or ``x``/``y`` outside [0, 2^z - 1]; the message names the value.
    """
    if not min_zoom <= z <= max_zoom:
        raise TileOutOfRange(f"zoom {z} is outside the served range [{min_zoom}, {max_zoom}]")
    n = 1 << z
    if not 0 <= x < n:
        raise TileOutOfRange(f"x {x} is outside [0, {n - 1}] at zoom {z}")
    if not 0 <= y < n:
        raise TileOutOfRange(f"y {y} is outside [0, {n - 1}] at zoom {z}")
    return Tile(z, x, y)


def check_fractional_zoom(z: int, zoom: float | None) -> float:
    """The zoom a tile is drawn at: ``zoom`` if given (it must lie in [z, z + 1)), else ``z``.

    Raises
    ------
    InvalidParameter
        ``zoom`` is not finite or outside [z, z + 1).
    """
    if zoom is None:
        return float(z)
    value = float(zoom)
    if not math.isfinite(value) or not z <= value < z + 1:
        raise InvalidParameter(f"zoom {zoom} must lie in [{z}, {z + 1}) for a tile of zoom {z}")
    return value


def tile_bounds(tile: Tile) -> Bounds:
    """EPSG:3857 bounds of a tile, metres.

    >>> tile_bounds(Tile(0, 0, 0)).maxx == HALF_WORLD_M
    True
    """
    size = 2 * HALF_WORLD_M / (1 << tile.z)
    minx = -HALF_WORLD_M + tile.x * size
    maxy = HALF_WORLD_M - tile.y * size
    return Bounds(minx, maxy - size, minx + size, maxy)


def buffered(bounds: Bounds, buffer_px: int, extent: int) -> Bounds:
    """The tile bounds grown by ``buffer_px`` grid units on each side (same units as ``bounds``)."""
    pad = (bounds.maxx - bounds.minx) * buffer_px / extent
    return Bounds(bounds.minx - pad, bounds.miny - pad, bounds.maxx + pad, bounds.maxy + pad)


def tile_center_latitude(tile: Tile) -> float:
    """Latitude of a tile's centre, degrees (the latitude its map scale is computed at)."""
    n = 1 << tile.z
    return math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * (tile.y + 0.5) / n))))


def mercator_to_lonlat(
    x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """EPSG:3857 metres to longitude/latitude degrees (spherical formulas, exact for Web Mercator)."""
    lon = np.degrees(np.asarray(x, dtype=float) / 6378137.0)
    lat = np.degrees(np.arctan(np.sinh(np.asarray(y, dtype=float) / 6378137.0)))
    return lon, lat


def lonlat_to_mercator(
    lon: NDArray[np.float64], lat: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Longitude/latitude degrees to EPSG:3857 metres (latitude clamped to Web Mercator's range)."""
    lat_c = np.clip(np.asarray(lat, dtype=float), -MAX_LATITUDE_DEG, MAX_LATITUDE_DEG)
    x = np.radians(np.asarray(lon, dtype=float)) * 6378137.0
    y = np.log(np.tan(np.pi / 4 + np.radians(lat_c) / 2)) * 6378137.0
    return x, y


def tiles_covering(bounds_3857: Bounds, z: int) -> list[Tile]:
    """Every tile of zoom ``z`` that intersects an EPSG:3857 rectangle, row by row."""
    n = 1 << z
    size = 2 * HALF_WORLD_M / n

    def col(v: float) -> int:
        return min(n - 1, max(0, int(math.floor((v + HALF_WORLD_M) / size))))

    def row(v: float) -> int:
        return min(n - 1, max(0, int(math.floor((HALF_WORLD_M - v) / size))))

    x0, x1 = col(bounds_3857.minx), col(bounds_3857.maxx)
    y0, y1 = row(bounds_3857.maxy), row(bounds_3857.miny)
    return [Tile(z, x, y) for y in range(y0, y1 + 1) for x in range(x0, x1 + 1)]


def quantize(coords: NDArray[np.float64], bounds: Bounds, extent: int) -> NDArray[np.int64]:
    """EPSG:3857 coordinates to integer tile-grid coordinates, y down: (n, 2) int64.

    >>> b = Bounds(0.0, 0.0, 4096.0, 4096.0)
    >>> quantize(np.array([[0.0, 4096.0], [10.4, 0.0]]), b, 4096).tolist()
    [[0, 0], [10, 4096]]
    """
    k = extent / (bounds.maxx - bounds.minx)
    out = np.empty(coords.shape, dtype=np.int64)
    np.rint((coords[:, 0] - bounds.minx) * k, out=out[:, 0], casting="unsafe")
    np.rint((bounds.maxy - coords[:, 1]) * k, out=out[:, 1], casting="unsafe")
    return out


def drop_repeats(q: NDArray[np.int64]) -> NDArray[np.int64]:
    """Drop consecutive duplicate rows of integer coordinates (the first of each run stays)."""
    if len(q) < 2:
        return q
    keep = np.empty(len(q), dtype=bool)
    keep[0] = True
    np.any(q[1:] != q[:-1], axis=1, out=keep[1:])
    return q if keep.all() else q[keep]


def clip_to_grid(q: NDArray[np.int64], lo: int, hi: int) -> list[NDArray[np.int64]]:
    """Clip an integer polyline to the square [lo, hi]²; returns its pieces (each >= 2 distinct points).

    Lines wholly inside come back unchanged without touching shapely; the rest go through
    ``shapely.clip_by_rect`` and are rounded back to the grid.
    """
    if len(q) < 2:
        return []
    if q.min() >= lo and q.max() <= hi:
        return [q]
    mins = q.min(axis=0)
    maxs = q.max(axis=0)
    if mins[0] > hi or mins[1] > hi or maxs[0] < lo or maxs[1] < lo:
        return []
    clipped = shapely.clip_by_rect(shapely.linestrings(q.astype(np.float64)), lo, lo, hi, hi)
    pieces = []
    for part in shapely.get_parts(clipped):
        if shapely.get_type_id(part) != 1:  # a point where the line only touches the rectangle
            continue
        xy = drop_repeats(np.rint(shapely.get_coordinates(part)).astype(np.int64))
        if len(xy) >= 2:
            pieces.append(xy)
    return pieces


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


def row_runs(chunks: NDArray[np.float64], box: Bounds, m: int, size: int = CHUNK_ROWS) -> list[tuple[int, int]]:
    """Row ranges [a, b) of the chunks that meet ``box``, consecutive chunks merged."""
    hit = (
        (chunks[:, 2] >= box.minx)
        & (chunks[:, 0] <= box.maxx)
        & (chunks[:, 3] >= box.miny)
        & (chunks[:, 1] <= box.maxy)
    )
    if hit.all():
        return [(0, m)]
    idx = np.flatnonzero(hit)
    if len(idx) == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    firsts = np.concatenate([idx[:1], idx[cut + 1]])
    lasts = np.concatenate([idx[cut], idx[-1:]])
    return [(int(a) * size, min((int(b) + 1) * size + 1, m)) for a, b in zip(firsts, lasts, strict=True)]


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


def clip_lines(
    q: NDArray[np.int64], lens: NDArray[np.int64], lo: int, hi: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`clip_to_grid` of many concatenated integer polylines in one vectorised shapely call.

    Returns
    -------
    (pts, piece_lens, src)
        The pieces' points concatenated, each piece's length (>= 2) and the input line it comes from
        (pieces in input order).
    """
    empty = np.zeros(0, dtype=np.int64)
    if len(lens) == 0:
        return np.zeros((0, 2), dtype=np.int64), empty, empty
    geoms = shapely.linestrings(q.astype(np.float64), indices=np.repeat(np.arange(len(lens)), lens))
    clipped = shapely.clip_by_rect(geoms, lo, lo, hi, hi)
    parts, src = shapely.get_parts(clipped, return_index=True)
    is_line = shapely.get_type_id(parts) == 1
    parts, src = parts[is_line], src[is_line]
    if len(parts) == 0:
        return np.zeros((0, 2), dtype=np.int64), empty, empty
    xy, which = shapely.get_coordinates(parts, return_index=True)
    out = np.rint(xy).astype(np.int64)
    keep = np.ones(len(out), dtype=bool)
    keep[1:] = (out[1:, 0] != out[:-1, 0]) | (out[1:, 1] != out[:-1, 1]) | (which[1:] != which[:-1])
    out, which = out[keep], which[keep]
    counts = np.bincount(which, minlength=len(parts))
    good = counts >= 2
    if not good.all():
        out = out[good[which]]
        counts, src = counts[good], src[good]
    return out, counts.astype(np.int64), src.astype(np.int64)


def clip_many(lines: Sequence[NDArray[np.int64]], lo: int, hi: int) -> list[list[NDArray[np.int64]]]:
    """:func:`clip_to_grid` of many integer polylines in one vectorised shapely call; pieces per input line."""
    out: list[list[NDArray[np.int64]]] = [[] for _ in lines]
    if not lines:
        return out
    lens = np.fromiter((len(v) for v in lines), dtype=np.int64, count=len(lines))
    pts, counts, src = clip_lines(np.concatenate(lines), lens, lo, hi)
    starts = np.cumsum(counts) - counts
    for s, n, i in zip(starts.tolist(), counts.tolist(), src.tolist(), strict=True):
        out[i].append(pts[s : s + n])
    return out


def row_runs_many(
    chunks: Sequence[NDArray[np.float64]], sizes: Sequence[int], box: Bounds, size: int = CHUNK_ROWS
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`row_runs` of many lines at once: (line index, first row, end row) of every run."""
    counts = np.fromiter((len(c) for c in chunks), dtype=np.int64, count=len(chunks))
    allc = np.concatenate(chunks)
    owner = np.repeat(np.arange(len(chunks)), counts)
    offset = np.cumsum(counts) - counts
    hit = (allc[:, 2] >= box.minx) & (allc[:, 0] <= box.maxx) & (allc[:, 3] >= box.miny) & (allc[:, 1] <= box.maxy)
    idx = np.flatnonzero(hit)
    if len(idx) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    own = owner[idx]
    cut = np.flatnonzero((np.diff(idx) > 1) | (np.diff(own) != 0))
    firsts = np.concatenate([idx[:1], idx[cut + 1]])
    lasts = np.concatenate([idx[cut], idx[-1:]])
    lines = owner[firsts]
    m = np.asarray(sizes, dtype=np.int64)[lines]
    a = (firsts - offset[lines]) * size
    b = np.minimum((lasts - offset[lines] + 1) * size + 1, m)
    return lines, a, b


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
def _clip_kernel(q, plen, lo, hi, out, out_len, out_src):  # pragma: no cover - compiled
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
                out[n, 0] = np.int64(np.rint(ax))
                out[n, 1] = np.int64(np.rint(ay))
                n += 1
            ix = np.int64(np.rint(bx))
            iy = np.int64(np.rint(by))
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
    q = np.ascontiguousarray(q, dtype=np.int64)
    lens = np.ascontiguousarray(lens, dtype=np.int64)
    out = np.empty((2 * len(q) + 2, 2), dtype=np.int64)
    out_len = np.empty(len(q) + 1, dtype=np.int64)
    out_src = np.empty(len(q) + 1, dtype=np.int64)
    n, m = _clip_kernel(q, lens, float(lo), float(hi), out, out_len, out_src)
    return out[:n], out_len[:m], out_src[:m]
