"""Bends of a line or ring (Wang & Müller 1998) and the geometric tests their operators need, compiled.

A *bend* is a maximal run of consecutive vertices whose turning angles have the same sign. Its polyline runs
from the vertex before the run to the vertex after it, and its *baseline* joins those two vertices; two
neighbouring bends share the segment between them (the inflection). Replacing a bend by its baseline removes
exactly the vertices of its run, so elimination keeps a subset of the input's vertices.

Everything here works on a compacted ``(m, 2)`` float64 array of the current vertices (metres); a ring is
given without its repeated first vertex and is treated cyclically, so a bend may wrap around the seam.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


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
    """
    m = xy.shape[0]
    empty = np.empty(0, np.int64)
    first = 0 if closed else 1
    cnt = m if closed else m - 2
    if cnt <= 0:
        return empty, empty, empty
    ang = turning_angles(xy, closed)
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
            return empty, empty, empty
        return np.array([1], np.int64), np.array([cnt], np.int64), np.array([1], np.int64)
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
            # Each gentle run takes the sign of the nearest non-gentle run before it (after it at a line's start).
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
        return empty, empty, empty
    bend_sign = np.empty(nr, np.int64)
    for r in range(nr):
        bend_sign[r] = sgn[starts[r]]
    return starts + first, lens, bend_sign


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
    b = (start + length) % m
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
        line_len += math.hypot(wx - ux, wy - uy)
        if j < length:
            turn += abs(ang[w])
        px = wx
        py = wy
    baseline = math.hypot(px, py)
    curvature = turn / line_len if line_len > 0.0 else 0.0
    return 0.5 * abs(twice), line_len + baseline, curvature, baseline


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
    if ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)) and ((d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)):
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
def _path_hits(
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
            if _path_hits(xy, a, b, path, u, w):
                return False
            u = w
        return True
    u = b
    while nxt[u] >= 0:
        w = nxt[u]
        if _path_hits(xy, a, b, path, u, w):
            return False
        u = w
    w = a
    while prv[w] >= 0:
        u = prv[w]
        if _path_hits(xy, a, b, path, u, w):
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
