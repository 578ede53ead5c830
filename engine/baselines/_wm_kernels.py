"""Compiled inner loops of Wang–Müller (numba), kept in one file on purpose.

numba's on-disk cache (``cache=True``) is invalidated only when the file that defines a function changes,
not when a function it calls from another file does; with the kernels split over several modules, an edit
to a callee would leave stale machine code in its callers' cache. So every compiled function the WM
operators use lives here, and :mod:`engine.baselines.wang_muller` holds the Python side.

Sections: bends (detection, measures), segment predicates, the segment grid, the operators.

Bends
-----
A *bend* is a maximal run of consecutive vertices whose turning angles have the same sign. Its polyline runs
from the vertex before the run to the vertex after it, and its *baseline* joins those two vertices; two
neighbouring bends share the segment between them (the inflection). Replacing a bend by its baseline removes
exactly the vertices of its run, so elimination keeps a subset of the input's vertices.

Everything works on a compacted ``(m, 2)`` float64 array of the current vertices (metres); a ring is given
without its repeated first vertex and is treated cyclically, so a bend may wrap around the seam.

Segment grid
------------
Without an index, each candidate edit scans every segment (:func:`path_is_clear`, kept as the O(m)
reference) and a round with ``k`` candidates costs O(k m); with :func:`build_index` a round costs O(m) to
build plus about O(1) per candidate. The grid is built once per round from the current vertices and then
kept *conservative*: a segment that an edit changes (its start vertex's link or coordinates) is marked stale
and moved to a short list that is checked linearly; a segment whose bounding box would cover too many cells
goes to that list from the start. The index is a tuple of arrays (numba has no cheap classes):
``(geo, dims, cell_start, items, stale, extras, counters, stamp)`` where ``geo = [x0, y0, cell]`` in metres,
``dims = [nx, ny]``, ``cell_start`` / ``items`` list the segments (by start vertex) of each cell (CSR),
``stale`` marks changed segments, ``extras[:counters[0]]`` is the linear list, ``counters[1]`` the current
query stamp and ``stamp`` the last query that visited each segment (so a segment in several cells is
checked once).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: ``0.75 / (4 pi)``: a bend's adjusted size ``0.75 A / cmp`` (``cmp = 4 pi A / P**2``) is ``ADJUST * P**2``.
ADJUST = 0.75 / (4.0 * math.pi)

#: A segment whose bounding box covers more cells than this goes to the grid's linear list: registering a
#: long diagonal segment in every cell it spans would cost more than checking it each time.
MAX_CELLS_PER_SEGMENT = 64


# --- bends -------------------------------------------------------------------------------------------------


@njit(cache=True)
def turning_angles(xy: np.ndarray, closed: bool) -> np.ndarray:  # pragma: no cover - compiled
    """Signed turning angle at every vertex, in radians (positive = left turn, 0 at a line's two ends).

    Parameters
    ----------
    xy
        (m, 2) float64 vertices in metres.
    closed
        Whether ``xy`` is a ring (then every vertex turns, cyclically).

    Returns
    -------
    (m,) float64 in [-pi, pi]; a zero-length segment gives 0.
    """
    m = xy.shape[0]
    ang = np.zeros(m)
    for i in range(m):
        if not closed and (i == 0 or i == m - 1):
            continue
        p = (i - 1 + m) % m
        q = (i + 1) % m
        ux = xy[i, 0] - xy[p, 0]
        uy = xy[i, 1] - xy[p, 1]
        vx = xy[q, 0] - xy[i, 0]
        vy = xy[q, 1] - xy[i, 1]
        ang[i] = math.atan2(ux * vy - uy * vx, ux * vx + uy * vy)
    return ang


@njit(cache=True)
def _runs(sgn: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Maximal runs of equal values in ``sgn``: (start position, length). A ring's runs start at a change."""
    cnt = sgn.shape[0]
    starts = np.empty(cnt, np.int64)
    lens = np.empty(cnt, np.int64)
    first = 0
    if closed:
        first = -1
        for q in range(cnt):
            if sgn[q] != sgn[(q - 1 + cnt) % cnt]:
                first = q
                break
        if first < 0:  # one sign all round: a single run with no start of its own
            starts[0] = 0
            lens[0] = cnt
            return starts[:1], lens[:1]
    nr = 0
    starts[0] = first
    lens[0] = 1
    for j in range(1, cnt):
        q = (first + j) % cnt
        if sgn[q] == sgn[(q - 1 + cnt) % cnt]:
            lens[nr] += 1
        else:
            nr += 1
            starts[nr] = q
            lens[nr] = 1
    return starts[: nr + 1], lens[: nr + 1]


@njit(cache=True)
def detect_bends(
    xy: np.ndarray, closed: bool, gentle_rad: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Bends of a line or ring, after merging gentle inflections into their neighbours.

    See :func:`bends_and_angles`, which also returns the turning angles.
    """
    start, length, sign, _ = bends_and_angles(xy, closed, gentle_rad)
    return start, length, sign


@njit(cache=True)
def bends_and_angles(
    xy: np.ndarray, closed: bool, gentle_rad: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Bends of a line or ring after merging gentle inflections into their neighbours, with turning angles.

    Vertices that do not turn (collinear, or a zero-length segment) take the sign of the vertex before them.
    A run of opposite turns whose *total* turning is below ``gentle_rad`` (a gentle inflection: a slight
    wobble that the eye does not read as a bend of its own) takes the sign of the preceding bend, which joins
    it and the following bend into one. A long, gently curving run keeps its own bend, because its total
    turning is large even when each vertex turns little.

    Parameters
    ----------
    xy
        (m, 2) float64 vertices in metres.
    closed
        Whether ``xy`` is a ring. A ring that turns one way all round (convex) has no bend.
    gentle_rad
        Total turning, in radians, below which a run is a gentle inflection.

    Returns
    -------
    start : (k,) int64
        Vertex index of each bend's first run vertex.
    length : (k,) int64
        Number of run vertices (the bend's polyline has ``length + 2`` vertices, from ``start - 1`` to
        ``start + length``, modulo ``m`` for a ring).
    sign : (k,) int64
        +1 for a left (counter-clockwise) bend, -1 for a right one. Neighbouring bends alternate.
    angles : (m,) float64
        :func:`turning_angles` of ``xy``.
    """
    m = xy.shape[0]
    empty = np.empty(0, np.int64)
    first = 0 if closed else 1
    cnt = m if closed else m - 2
    ang = turning_angles(xy, closed)
    if cnt <= 0:
        return empty, empty, empty, ang
    sgn = np.zeros(cnt, np.int64)
    last = 0
    for q in range(cnt):
        a = ang[first + q]
        if a > 0.0:
            sgn[q] = 1
        elif a < 0.0:
            sgn[q] = -1
        if sgn[q] != 0:
            last = sgn[q]
    if last == 0:  # nothing turns: a straight line is one flat bend, a flat ring none
        if closed:
            return empty, empty, empty, ang
        return np.array([1], np.int64), np.array([cnt], np.int64), np.array([1], np.int64), ang
    # A vertex that does not turn joins the run before it (cyclically for a ring; at a line's start, the
    # first turning vertex's run).
    prev = last if closed else 0
    for q in range(cnt):
        if sgn[q] == 0:
            sgn[q] = prev
        else:
            prev = sgn[q]
    if not closed:
        for q in range(cnt):
            if sgn[q] != 0:
                break
        lead = sgn[q]
        for q in range(cnt):
            if sgn[q] != 0:
                break
            sgn[q] = lead
    starts, lens = _runs(sgn, closed)
    nr = starts.shape[0]
    if nr > 1:
        gentle = np.zeros(nr, np.bool_)
        n_gentle = 0
        for r in range(nr):
            tot = 0.0
            for j in range(lens[r]):
                tot += abs(ang[first + (starts[r] + j) % cnt])
            if tot < gentle_rad:
                gentle[r] = True
                n_gentle += 1
        if n_gentle == nr:
            sgn[:] = 1  # nothing but wobbles: one bend for a line, none for a ring
        elif n_gentle > 0:
            new_sign = np.empty(nr, np.int64)
            for r in range(nr):
                new_sign[r] = sgn[starts[r]]
            # Each gentle run takes the sign of the nearest non-gentle run before it (after it, at a line's
            # start).
            for r in range(nr):
                if not gentle[r]:
                    continue
                s = 0
                for back in range(1, nr + 1):
                    rr = r - back
                    if rr < 0:
                        if not closed:
                            break
                        rr += nr
                    if not gentle[rr]:
                        s = sgn[starts[rr]]
                        break
                if s == 0:
                    for rr in range(r + 1, nr):
                        if not gentle[rr]:
                            s = sgn[starts[rr]]
                            break
                new_sign[r] = s
            for r in range(nr):
                for j in range(lens[r]):
                    sgn[(starts[r] + j) % cnt] = new_sign[r]
        if n_gentle > 0:
            starts, lens = _runs(sgn, closed)
            nr = starts.shape[0]
    if closed and nr == 1:
        return empty, empty, empty, ang
    bend_sign = np.empty(nr, np.int64)
    for r in range(nr):
        bend_sign[r] = sgn[starts[r]]
    return starts + first, lens, bend_sign, ang


@njit(cache=True)
def bend_measures(
    xy: np.ndarray, closed: bool, start: int, length: int, ang: np.ndarray
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """Area, perimeter, curvature and baseline length of one bend.

    Parameters
    ----------
    xy
        (m, 2) float64 vertices in metres.
    closed
        Whether ``xy`` is a ring.
    start, length
        The bend's run, as returned by :func:`detect_bends`.
    ang
        (m,) turning angles from :func:`turning_angles`.

    Returns
    -------
    area
        Area in m² of the polygon bend + baseline (absolute shoelace value).
    perimeter
        Length in m of the bend's polyline plus its baseline.
    curvature
        Total absolute turning of the run divided by the polyline's length, in rad/m (0 for zero length).
    baseline
        Length of the baseline in m.
    """
    m = xy.shape[0]
    a = (start - 1 + m) % m
    x0 = xy[a, 0]
    y0 = xy[a, 1]
    twice = 0.0
    line_len = 0.0
    turn = 0.0
    px = 0.0
    py = 0.0
    for j in range(length + 1):
        u = (a + j) % m
        w = (a + j + 1) % m
        ux = xy[u, 0] - x0
        uy = xy[u, 1] - y0
        wx = xy[w, 0] - x0
        wy = xy[w, 1] - y0
        # Shoelace relative to the first vertex: the closing baseline then adds nothing.
        twice += ux * wy - wx * uy
        line_len += math.sqrt((wx - ux) * (wx - ux) + (wy - uy) * (wy - uy))
        if j < length:
            turn += abs(ang[w])
        px = wx
        py = wy
    baseline = math.sqrt(px * px + py * py)
    curvature = turn / line_len if line_len > 0.0 else 0.0
    return 0.5 * abs(twice), line_len + baseline, curvature, baseline


# --- segment predicates ------------------------------------------------------------------------------------


@njit(cache=True)
def _orient(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:  # pragma: no cover
    """Twice the signed area of triangle abc (> 0 when c lies left of a->b)."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True)
def _on_segment(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> bool:  # pragma: no cover
    """Whether c, known to be collinear with a and b, lies on the closed segment ab."""
    return min(ax, bx) <= cx <= max(ax, bx) and min(ay, by) <= cy <= max(ay, by)


@njit(cache=True)
def segments_meet(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> bool:  # pragma: no cover - compiled
    """Whether the closed segments ab and cd share any point (a crossing, a touch or an overlap)."""
    if max(ax, bx) < min(cx, dx) or max(cx, dx) < min(ax, bx):
        return False
    if max(ay, by) < min(cy, dy) or max(cy, dy) < min(ay, by):
        return False
    d1 = _orient(cx, cy, dx, dy, ax, ay)
    d2 = _orient(cx, cy, dx, dy, bx, by)
    d3 = _orient(ax, ay, bx, by, cx, cy)
    d4 = _orient(ax, ay, bx, by, dx, dy)
    straddle_cd = (d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)
    straddle_ab = (d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)
    if straddle_cd and straddle_ab:
        return True
    if d1 == 0.0 and _on_segment(cx, cy, dx, dy, ax, ay):
        return True
    if d2 == 0.0 and _on_segment(cx, cy, dx, dy, bx, by):
        return True
    if d3 == 0.0 and _on_segment(ax, ay, bx, by, cx, cy):
        return True
    if d4 == 0.0 and _on_segment(ax, ay, bx, by, dx, dy):
        return True
    return False


@njit(cache=True)
def _fold_back(sx: float, sy: float, tx: float, ty: float, ux: float, uy: float) -> bool:  # pragma: no cover
    """Whether segments s->t and s->u, which share the vertex s, overlap (collinear, same direction)."""
    cross = (tx - sx) * (uy - sy) - (ty - sy) * (ux - sx)
    dot = (tx - sx) * (ux - sx) + (ty - sy) * (uy - sy)
    return cross == 0.0 and dot > 0.0


@njit(cache=True)
def path_hits(
    xy: np.ndarray, a: int, b: int, path: np.ndarray, u: int, w: int
) -> bool:  # pragma: no cover - compiled
    """Whether the new path a -> ... -> b meets the kept segment u -> w anywhere it must not.

    Segments that share the vertex ``a`` or ``b`` by identity meet there by construction; they only count
    when they fold back onto each other. Every other contact is a new intersection.
    """
    k = path.shape[0] - 1
    ux = xy[u, 0]
    uy = xy[u, 1]
    wx = xy[w, 0]
    wy = xy[w, 1]
    for j in range(k):
        p0x = path[j, 0]
        p0y = path[j, 1]
        p1x = path[j + 1, 0]
        p1y = path[j + 1, 1]
        at_a = j == 0 and (u == a or w == a)
        at_b = j == k - 1 and (u == b or w == b)
        if at_a and at_b:
            return True  # the kept segment is the new one reversed: the ring would have two vertices
        if at_a:
            ox = wx if u == a else ux
            oy = wy if u == a else uy
            if _fold_back(p0x, p0y, p1x, p1y, ox, oy):
                return True
        elif at_b:
            ox = wx if u == b else ux
            oy = wy if u == b else uy
            if _fold_back(p1x, p1y, p0x, p0y, ox, oy):
                return True
        elif segments_meet(p0x, p0y, p1x, p1y, ux, uy, wx, wy):
            return True
    return False


@njit(cache=True)
def path_is_clear(
    xy: np.ndarray, prv: np.ndarray, nxt: np.ndarray, closed: bool, a: int, b: int, path: np.ndarray
) -> bool:  # pragma: no cover - compiled
    """Whether replacing the vertices strictly between ``a`` and ``b`` by ``path`` keeps the line free of
    any intersection the line did not already have.

    Parameters
    ----------
    xy
        (m, 2) float64 current vertices in metres.
    prv, nxt
        (m,) int64 links of the vertices still alive (-1 past a line's ends); the run between ``a`` and ``b``
        is still linked and is skipped.
    closed
        Whether the line is a ring.
    a, b
        Vertices that stay: the path starts at ``a`` and ends at ``b`` (``b`` follows ``a`` along the line).
    path
        (k + 1, 2) float64 path coordinates, ``path[0] = xy[a]`` and ``path[k] = xy[b]``.

    Returns
    -------
    bool
        True when no segment of the path meets a kept segment (except where they share ``a`` or ``b``
        without folding back) - an O(m) scan.
    """
    if closed:
        u = b
        while u != a:
            w = nxt[u]
            if path_hits(xy, a, b, path, u, w):
                return False
            u = w
        return True
    u = b
    while nxt[u] >= 0:
        w = nxt[u]
        if path_hits(xy, a, b, path, u, w):
            return False
        u = w
    w = a
    while prv[w] >= 0:
        u = prv[w]
        if path_hits(xy, a, b, path, u, w):
            return False
        w = u
    return True


@njit(cache=True)
def init_links(m: int, closed: bool) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Previous / next links of ``m`` vertices in line order (cyclic for a ring, -1 past a line's ends)."""
    prv = np.empty(m, np.int64)
    nxt = np.empty(m, np.int64)
    for i in range(m):
        prv[i] = i - 1
        nxt[i] = i + 1
    if closed:
        prv[0] = m - 1
        nxt[m - 1] = 0
    else:
        nxt[m - 1] = -1
    return prv, nxt


# --- segment grid ------------------------------------------------------------------------------------------


@njit(cache=True)
def _cell(v: float, origin: float, size: float, count: int) -> int:  # pragma: no cover - compiled
    """Cell index of coordinate ``v``, clamped to the grid (so queries outside it still find its edge)."""
    c = int(math.floor((v - origin) / size))
    if c < 0:
        return 0
    if c >= count:
        return count - 1
    return c


@njit(cache=True)
def build_index(xy: np.ndarray, nxt: np.ndarray):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Grid of the segments ``u -> nxt[u]`` of a line or ring (all vertices alive, ``nxt = -1`` at the end).

    Parameters
    ----------
    xy
        (m, 2) float64 vertices in metres.
    nxt
        (m,) int64 next-vertex links.

    Returns
    -------
    tuple
        The index described in the module docstring. Cells are about one mean segment long (at least
        ``sqrt(area / m)``) and there are at most ``4 m + 16`` of them.
    """
    m = xy.shape[0]
    x0 = xy[0, 0]
    y0 = xy[0, 1]
    x1 = x0
    y1 = y0
    total = 0.0
    nseg = 0
    for u in range(m):
        x0 = min(x0, xy[u, 0])
        x1 = max(x1, xy[u, 0])
        y0 = min(y0, xy[u, 1])
        y1 = max(y1, xy[u, 1])
        w = nxt[u]
        if w >= 0:
            total += math.hypot(xy[w, 0] - xy[u, 0], xy[w, 1] - xy[u, 1])
            nseg += 1
    width = x1 - x0
    height = y1 - y0
    size = max(total / max(nseg, 1), math.sqrt(width * height / max(m, 1)))
    if not size > 0.0:
        size = 1.0
    nx = int(width / size) + 1
    ny = int(height / size) + 1
    limit = 4 * m + 16
    while nx * ny > limit:
        size *= 1.5
        nx = int(width / size) + 1
        ny = int(height / size) + 1
    counts = np.zeros(nx * ny + 1, np.int64)
    extras = np.empty(3 * m + 8, np.int64)
    counters = np.zeros(2, np.int64)
    big = np.zeros(m, np.bool_)
    for u in range(m):
        w = nxt[u]
        if w < 0:
            continue
        cx0 = _cell(min(xy[u, 0], xy[w, 0]), x0, size, nx)
        cx1 = _cell(max(xy[u, 0], xy[w, 0]), x0, size, nx)
        cy0 = _cell(min(xy[u, 1], xy[w, 1]), y0, size, ny)
        cy1 = _cell(max(xy[u, 1], xy[w, 1]), y0, size, ny)
        if (cx1 - cx0 + 1) * (cy1 - cy0 + 1) > MAX_CELLS_PER_SEGMENT:
            big[u] = True
            extras[counters[0]] = u
            counters[0] += 1
            continue
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                counts[cy * nx + cx + 1] += 1
    cell_start = np.cumsum(counts)
    items = np.empty(cell_start[-1], np.int64)
    fill = cell_start[:-1].copy()
    for u in range(m):
        w = nxt[u]
        if w < 0 or big[u]:
            continue
        cx0 = _cell(min(xy[u, 0], xy[w, 0]), x0, size, nx)
        cx1 = _cell(max(xy[u, 0], xy[w, 0]), x0, size, nx)
        cy0 = _cell(min(xy[u, 1], xy[w, 1]), y0, size, ny)
        cy1 = _cell(max(xy[u, 1], xy[w, 1]), y0, size, ny)
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                c = cy * nx + cx
                items[fill[c]] = u
                fill[c] += 1
    geo = np.array([x0, y0, size])
    dims = np.array([nx, ny], np.int64)
    stale = np.zeros(m, np.bool_)
    stamp = np.zeros(m, np.int64)
    return geo, dims, cell_start, items, stale, extras, counters, stamp


@njit(cache=True)
def mark_changed(index, u: int) -> None:  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Record that the segment starting at vertex ``u`` has a new end or new coordinates."""
    stale = index[4]
    extras = index[5]
    counters = index[6]
    if not stale[u]:
        stale[u] = True
        extras[counters[0]] = u
        counters[0] += 1


@njit(cache=True)
def _check(
    xy: np.ndarray, nxt: np.ndarray, dead: np.ndarray, a: int, b: int, start: int, length: int,
    path: np.ndarray, stamp: np.ndarray, sid: int, u: int,
) -> bool:  # pragma: no cover - compiled
    """Whether the kept segment starting at ``u`` (if it is kept and not yet visited) meets the path."""
    if stamp[u] == sid:
        return False
    stamp[u] = sid
    if dead[u] or u == a:
        return False
    m = xy.shape[0]
    if (u - start + m) % m < length:
        return False  # a segment of the run being replaced
    w = nxt[u]
    if w < 0:
        return False
    return path_hits(xy, a, b, path, u, w)


@njit(cache=True)
def index_path_is_clear(  # type: ignore[no-untyped-def]
    xy: np.ndarray, nxt: np.ndarray, dead: np.ndarray, index, a: int, b: int, start: int, length: int,
    path: np.ndarray,
) -> bool:  # pragma: no cover - compiled
    """Whether replacing the run ``start .. start + length - 1`` (between ``a`` and ``b``) by ``path`` keeps
    the line free of new intersections; the grid version of :func:`path_is_clear`.

    Parameters
    ----------
    xy
        (m, 2) float64 current vertices in metres (coordinates may have changed since the build: changed
        segments are stale and checked from the linear list).
    nxt
        (m,) int64 current links.
    dead
        (m,) bool, vertices removed since the build.
    index
        From :func:`build_index`.
    a, b, start, length
        The vertices that stay at both ends and the run between them.
    path
        (k + 1, 2) float64 new coordinates from ``xy[a]`` to ``xy[b]``.
    """
    geo, dims, cell_start, items, stale, extras, counters, stamp = index
    counters[1] += 1
    sid = counters[1]
    x0 = geo[0]
    y0 = geo[1]
    size = geo[2]
    nx = dims[0]
    ny = dims[1]
    for j in range(path.shape[0] - 1):
        cx0 = _cell(min(path[j, 0], path[j + 1, 0]), x0, size, nx)
        cx1 = _cell(max(path[j, 0], path[j + 1, 0]), x0, size, nx)
        cy0 = _cell(min(path[j, 1], path[j + 1, 1]), y0, size, ny)
        cy1 = _cell(max(path[j, 1], path[j + 1, 1]), y0, size, ny)
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                c = cy * nx + cx
                for t in range(cell_start[c], cell_start[c + 1]):
                    u = items[t]
                    if stale[u]:
                        continue
                    if _check(xy, nxt, dead, a, b, start, length, path, stamp, sid, u):
                        return False
    for t in range(counters[0]):
        if _check(xy, nxt, dead, a, b, start, length, path, stamp, sid, extras[t]):
            return False
    return True


# --- operators ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _measure_all(
    xy: np.ndarray, closed: bool, start: np.ndarray, length: np.ndarray, ang: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Adjusted size (m²), compactness, curvature (rad/m) and baseline length (m) of every bend."""
    nb = start.shape[0]
    adj = np.empty(nb)
    cmp = np.empty(nb)
    curv = np.empty(nb)
    base = np.empty(nb)
    for k in range(nb):
        area, perim, c, bl = bend_measures(xy, closed, start[k], length[k], ang)
        adj[k] = ADJUST * perim * perim
        cmp[k] = 4.0 * math.pi * area / (perim * perim) if perim > 0.0 else 0.0
        curv[k] = c
        base[k] = bl
    return adj, cmp, curv, base


@njit(cache=True)
def _links_and_index(cur: np.ndarray, closed: bool):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The next-vertex links of a line not yet changed and the segment grid over it (:func:`build_index`)."""
    _, nxt = init_links(cur.shape[0], closed)
    return nxt, build_index(cur, nxt)


@njit(cache=True)
def _try_eliminate(  # type: ignore[no-untyped-def]
    xy: np.ndarray,
    closed: bool,
    nxt: np.ndarray,
    dead: np.ndarray,
    index,
    alive: int,
    start: int,
    length: int,
) -> bool:  # pragma: no cover - compiled
    """Replace one bend by its baseline if the line stays free of new intersections (and a ring keeps a
    triangle); update the links, the ``dead`` mask and the segment grid. Returns whether it was done."""
    m = xy.shape[0]
    if closed and alive - length < 3:
        return False
    a = (start - 1 + m) % m
    b = (start + length) % m
    path = np.empty((2, 2))
    path[0, 0] = xy[a, 0]
    path[0, 1] = xy[a, 1]
    path[1, 0] = xy[b, 0]
    path[1, 1] = xy[b, 1]
    if not index_path_is_clear(xy, nxt, dead, index, a, b, start, length, path):
        return False
    for j in range(length):
        dead[(start + j) % m] = True
    nxt[a] = b
    mark_changed(index, a)
    return True


@njit(cache=True)
def _block(blocked: np.ndarray, k: int, closed: bool) -> None:  # pragma: no cover - compiled
    """Mark bend ``k`` and its neighbours as changed in this round (their measures are now stale)."""
    nb = blocked.shape[0]
    blocked[k] = True
    if k > 0:
        blocked[k - 1] = True
    elif closed:
        blocked[nb - 1] = True
    if k < nb - 1:
        blocked[k + 1] = True
    elif closed:
        blocked[0] = True


@njit(cache=True)
def _eliminate_smallest(
    cur: np.ndarray,
    closed: bool,
    dead: np.ndarray,
    start: np.ndarray,
    length: np.ndarray,
    adj: np.ndarray,
    allowed: np.ndarray,
    budget: int,
) -> int:  # pragma: no cover - compiled
    """Replace up to ``budget`` of the ``allowed`` bends by their baselines, smallest adjusted size first (equal
    sizes in line order), never two neighbours in one round. Returns how many were replaced."""
    nxt, index = _links_and_index(cur, closed)
    blocked = np.zeros(start.shape[0], np.bool_)
    alive = cur.shape[0]
    done = 0
    for k in np.argsort(adj, kind="mergesort"):
        if done >= budget:
            break
        if not allowed[k] or blocked[k]:
            continue
        if _try_eliminate(cur, closed, nxt, dead, index, alive, start[k], length[k]):
            alive -= length[k]
            _block(blocked, k, closed)
            done += 1
    return done


@njit(cache=True)
def wm_ladder_removal(
    xy: np.ndarray, closed: bool, gentle_rad: float, targets: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """Level at which each vertex leaves the Wang–Müller ladder.

    For each level ``l = 1 .. len(targets)`` bends are eliminated, smallest adjusted size first, until at
    most ``targets[l - 1]`` bends remain. A round eliminates up to half the remaining excess (at least one)
    among bends that are not neighbours of each other, then the bends are recomputed. Eliminations that would
    make the line cross itself (or leave a ring with fewer than three vertices) are refused; if every
    candidate is refused, the ladder stays where it is.

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres.
    closed
        Whether ``xy`` is a ring.
    gentle_rad
        Gentle-inflection threshold in radians (see :func:`detect_bends`).
    targets
        (levels - 2,) int64 bend count allowed at levels 1 .. levels - 2.

    Returns
    -------
    (n,) int64
        The first level that no longer has the vertex; ``len(targets) + 1`` for vertices never removed
        here (the caller builds the last, minimal level itself).
    """
    n = xy.shape[0]
    never = targets.shape[0] + 1
    removed_at = np.full(n, never, np.int64)
    idx = np.arange(n)
    for lv in range(targets.shape[0]):
        target = targets[lv]
        while True:
            cur = xy[idx]
            m = cur.shape[0]
            start, length, _, ang = bends_and_angles(cur, closed, gentle_rad)
            nb = start.shape[0]
            if nb <= target:
                break
            adj, _, _, _ = _measure_all(cur, closed, start, length, ang)
            budget = max(1, (nb - target) // 2)
            dead = np.zeros(m, np.bool_)
            done = _eliminate_smallest(cur, closed, dead, start, length, adj, np.ones(nb, np.bool_), budget)
            if done == 0:
                return removed_at  # stuck: no bend can go without a crossing
            for v in range(m):
                if dead[v]:
                    removed_at[idx[v]] = lv + 1
            idx = idx[~dead]
    return removed_at


@njit(cache=True)
def _stretch(
    xy: np.ndarray, a: int, b: int, start: int, length: int, f: float, out: np.ndarray
) -> float:  # pragma: no cover - compiled
    """Stretch a bend's run away from its baseline by ``f`` into ``out`` ((length + 2, 2), with a and b at
    the ends); returns the stretched bend's perimeter (polyline + baseline) in m."""
    m = xy.shape[0]
    ax = xy[a, 0]
    ay = xy[a, 1]
    bx = xy[b, 0]
    by = xy[b, 1]
    bl = math.hypot(bx - ax, by - ay)
    ux = (bx - ax) / bl
    uy = (by - ay) / bl
    out[0, 0] = ax
    out[0, 1] = ay
    for j in range(length):
        v = (start + j) % m
        px = xy[v, 0] - ax
        py = xy[v, 1] - ay
        t = px * ux + py * uy
        h = -px * uy + py * ux
        out[j + 1, 0] = ax + t * ux - f * h * uy
        out[j + 1, 1] = ay + t * uy + f * h * ux
    out[length + 1, 0] = bx
    out[length + 1, 1] = by
    perim = bl
    for j in range(length + 1):
        perim += math.hypot(out[j + 1, 0] - out[j, 0], out[j + 1, 1] - out[j, 1])
    return perim


@njit(cache=True)
def _exaggerate(
    cur: np.ndarray,
    closed: bool,
    moved: np.ndarray,
    start: np.ndarray,
    length: np.ndarray,
    adj: np.ndarray,
    curv: np.ndarray,
    base: np.ndarray,
    small: np.ndarray,
    ref: float,
    isolation_ratio: float,
    max_stretch: float,
) -> bool:  # pragma: no cover - compiled
    """Exaggerate every isolated small bend up to the reference size (in place). Returns whether any was."""
    m = cur.shape[0]
    nb = start.shape[0]
    if nb < 3:
        return False
    nxt, index = _links_and_index(cur, closed)
    dead = np.zeros(m, np.bool_)
    blocked = np.zeros(nb, np.bool_)
    changed = False
    for k in range(nb):
        if not small[k] or blocked[k] or base[k] <= 0.0:
            continue
        if not closed and (k == 0 or k == nb - 1):
            continue  # an end bend has one neighbour: nothing says it stands alone
        left = k - 1 if k > 0 else nb - 1
        right = k + 1 if k < nb - 1 else 0
        if curv[left] > isolation_ratio * curv[k] or curv[right] > isolation_ratio * curv[k]:
            continue
        already = False
        for j in range(length[k]):
            if moved[(start[k] + j) % m]:
                already = True
        if already:
            continue  # each bend is exaggerated once; the loop then cannot cycle
        a = (start[k] - 1 + m) % m
        b = (start[k] + length[k]) % m
        path = np.empty((length[k] + 2, 2))
        if ADJUST * _stretch(cur, a, b, start[k], length[k], max_stretch, path) ** 2 < ref:
            continue
        lo = 1.0
        hi = max_stretch
        for _ in range(40):  # bisection on the stretch: the perimeter grows with it
            mid = 0.5 * (lo + hi)
            if ADJUST * _stretch(cur, a, b, start[k], length[k], mid, path) ** 2 < ref:
                lo = mid
            else:
                hi = mid
        _stretch(cur, a, b, start[k], length[k], hi, path)
        if not index_path_is_clear(cur, nxt, dead, index, a, b, start[k], length[k], path):
            continue
        mark_changed(index, a)
        for j in range(length[k]):
            v = (start[k] + j) % m
            cur[v, 0] = path[j + 1, 0]
            cur[v, 1] = path[j + 1, 1]
            moved[v] = True
            mark_changed(index, v)
        _block(blocked, k, closed)
        changed = True
    return changed


@njit(cache=True)
def _combine(
    cur: np.ndarray,
    closed: bool,
    dead: np.ndarray,
    start: np.ndarray,
    length: np.ndarray,
    adj: np.ndarray,
    cmp: np.ndarray,
    small: np.ndarray,
    size_ratio: float,
    cmp_diff: float,
) -> bool:  # pragma: no cover - compiled
    """Combine each run of three or more similar small bends into fewer, larger bends.

    In a run ``b_s .. b_e`` of neighbouring small bends, each similar to the next, the bends ``b_s+1``,
    ``b_s+3``, ... (the ones that turn the other way) are replaced by their baselines. That joins
    ``b_s``, ``b_s+2``, ... into one bend that spans the run and keeps the outer vertices of the originals:
    the wiggly stretch becomes one bend instead of vanishing under elimination. Runs do not wrap around a
    ring's seam.
    """
    nb = start.shape[0]
    nxt, index = _links_and_index(cur, closed)
    alive = cur.shape[0]
    changed = False
    k = 0
    while k < nb:
        if not small[k]:
            k += 1
            continue
        e = k
        while e + 1 < nb and small[e + 1]:
            lo = min(adj[e], adj[e + 1])
            hi = max(adj[e], adj[e + 1])
            if lo < size_ratio * hi or abs(cmp[e] - cmp[e + 1]) > cmp_diff:
                break
            e += 1
        if e - k >= 2:
            for j in range(k + 1, e, 2):
                if _try_eliminate(cur, closed, nxt, dead, index, alive, start[j], length[j]):
                    alive -= length[j]
                    changed = True
        k = e + 1
    return changed


@njit(cache=True)
def wm_generalize(
    xy: np.ndarray,
    closed: bool,
    ref: float,
    gentle_rad: float,
    isolation_ratio: float,
    max_stretch: float,
    size_ratio: float,
    cmp_diff: float,
    max_iter: int,
) -> np.ndarray:  # pragma: no cover - compiled
    """Wang–Müller at one reference size: the operators, in order, until none changes the line.

    Each pass detects the bends, then applies the first operator that changes something - exaggeration of
    isolated small bends, combination of runs of similar small bends, elimination of small bends - and
    starts again. A bend is small when its adjusted size is below ``ref`` (m²).

    Returns
    -------
    (k, 2) float64
        The generalized line; vertices are input vertices except those of exaggerated bends.
    """
    cur = xy.copy()
    moved = np.zeros(cur.shape[0], np.bool_)
    for _ in range(max_iter):
        start, length, _, ang = bends_and_angles(cur, closed, gentle_rad)
        nb = start.shape[0]
        if nb == 0:
            break
        adj, cmp, curv, base = _measure_all(cur, closed, start, length, ang)
        small = adj < ref
        if not small.any():
            break
        if _exaggerate(
            cur, closed, moved, start, length, adj, curv, base, small, ref, isolation_ratio, max_stretch
        ):
            continue
        dead = np.zeros(cur.shape[0], np.bool_)
        if not _combine(cur, closed, dead, start, length, adj, cmp, small, size_ratio, cmp_diff):
            if _eliminate_smallest(cur, closed, dead, start, length, adj, small, nb) == 0:
                break
        keep = ~dead
        cur = cur[keep]
        moved = moved[keep]
    return cur
