"""Which pieces of contour lie near each other, compiled: the pairs of boxes that meet, and the distance between
two pieces' rows (docs/design.md section 4.8).

The crossing repair asks both questions for hundreds of thousands of pieces per block. A shapely STRtree and
``shapely.distance`` answer them too, but need a geometry object per box and per piece, which cost more than
the answers; these kernels work on the arrays themselves and give the same answers: the same pairs as an
STRtree query of boxes (boxes that only touch meet), and the distance ``shapely.distance`` gives between two
linestrings: the smallest segment-to-segment distance, each from the textbook formulas (the projection parameter
of a point on a segment, the perpendicular distance by the cross product, the parametric intersection test),
evaluated in an order whose rounding agrees with shapely's to the last bit (tests/engine/ccsm/test_near.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


def box_pairs(a: NDArray[np.floating], b: NDArray[np.floating]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every pair (i, j) of a box ``a[i]`` and a box ``b[j]`` that meet (closed boxes: touching counts), sorted
    by i, then j. Boxes are rows (minx, miny, maxx, maxy).

    A sort and sweep along x: each pair is found from the box whose minx is smaller (ties from ``a``'s side),
    so only boxes that overlap in x are compared.

    >>> box_pairs(np.array([[0.0, 0, 1, 1], [5, 5, 6, 6]]), np.array([[1.0, 1, 2, 2], [2, 0, 3, 1], [0, 0, 6, 0]]))
    (array([0, 0]), array([0, 2]))
    """
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.ascontiguousarray(b, dtype=np.float64).reshape(-1, 4)
    oa = np.argsort(a[:, 0], kind="stable")
    ob = np.argsort(b[:, 0], kind="stable")
    ax, bx = a[oa, 0], b[ob, 0]
    none = np.zeros(0, dtype=np.intp)
    count = _sweep(a, b, oa, ob, ax, bx, none, none, False)
    ia, ib = np.empty(count, dtype=np.intp), np.empty(count, dtype=np.intp)
    _sweep(a, b, oa, ob, ax, bx, ia, ib, True)
    order = np.lexsort((ib, ia))
    return ia[order], ib[order]


@njit(cache=True, nogil=True)
def _sweep(a, b, oa, ob, ax, bx, ia, ib, fill):  # pragma: no cover - compiled
    """Count (``fill`` False) or write the pairs of :func:`box_pairs`; ``ax``, ``bx`` the sorted minx."""
    n = 0
    for i in range(len(a)):  # b's minx in [a's minx, a's maxx]
        n = _scan(a[i], b, ob, bx, np.searchsorted(bx, a[i, 0]), i, True, ia, ib, n, fill)
    for j in range(len(b)):  # a's minx in (b's minx, b's maxx]: the pairs not found above
        n = _scan(b[j], a, oa, ax, np.searchsorted(ax, b[j, 0], side="right"), j, False, ia, ib, n, fill)
    return n


@njit(cache=True, nogil=True)
def _scan(box, others, order, minx, k, at, box_is_a, ia, ib, n, fill):  # pragma: no cover - compiled
    """From sorted position ``k`` on, the ``others`` whose minx is within ``box``'s x range and that meet it in
    y: each written (``box`` at index ``at``, on a's side if ``box_is_a``) and counted; returns the new count."""
    while k < len(minx) and minx[k] <= box[2]:
        j = order[k]
        if others[j, 1] <= box[3] and box[1] <= others[j, 3]:
            if fill:
                ia[n] = at if box_is_a else j
                ib[n] = j if box_is_a else at
            n += 1
        k += 1
    return n


def boxes_meeting(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Whether each box ``b[j]`` meets some box of ``a`` (closed boxes: touching counts): the js of
    :func:`box_pairs` as a mask, without listing the pairs (a block asks only which pieces its own ones meet).

    The same sweep along x, from each side: every ``b`` box whose minx lies in an ``a`` box's x range, then, for
    the ``b`` boxes not yet met, every ``a`` box whose minx lies in theirs, stopping at the first that meets.

    >>> boxes_meeting(np.array([[0.0, 0, 1, 1], [5, 5, 6, 6]]), np.array([[1.0, 1, 2, 2], [2, 0, 3, 1], [0, 0, 6, 0]]))
    array([ True, False,  True])
    """
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.ascontiguousarray(b, dtype=np.float64).reshape(-1, 4)
    oa = np.argsort(a[:, 0], kind="stable")
    ob = np.argsort(b[:, 0], kind="stable")
    met = np.zeros(len(b), dtype=np.bool_)
    _mark_met(a, b, oa, ob, a[oa, 0], b[ob, 0], met)
    return met


@njit(cache=True, nogil=True)
def _mark_met(a, b, oa, ob, ax, bx, met):  # pragma: no cover - compiled
    """Set ``met[j]`` for every ``b`` box that meets an ``a`` box; ``ax``, ``bx`` the sorted minx."""
    for i in range(len(a)):  # b's minx in [a's minx, a's maxx]
        k = np.searchsorted(bx, a[i, 0])
        while k < len(bx) and bx[k] <= a[i, 2]:
            j = ob[k]
            if not met[j] and b[j, 1] <= a[i, 3] and a[i, 1] <= b[j, 3]:
                met[j] = True
            k += 1
    for j in range(len(b)):  # a's minx in (b's minx, b's maxx]: the boxes not met above
        if met[j]:
            continue
        k = np.searchsorted(ax, b[j, 0], side="right")
        while k < len(ax) and ax[k] <= b[j, 2]:
            i = oa[k]
            if a[i, 1] <= b[j, 3] and b[j, 1] <= a[i, 3]:
                met[j] = True
                break
            k += 1


def piece_gaps(
    points: NDArray[np.float64],
    first: NDArray[np.intp],
    last: NDArray[np.intp],
    p: NDArray[np.intp],
    q: NDArray[np.intp],
    limit: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Distance between pieces ``p[k]`` and ``q[k]`` of ``points`` (a piece: the polyline of points first..last),
    for every k: what ``shapely.distance`` gives for their linestrings.

    With ``limit``, only the gaps up to ``limit[k]`` are wanted: those are the same numbers, every other is some
    number above its limit (a pair of pieces whose boxes are farther apart, and every pair of segments that is,
    is not measured; most of the crossing check's candidate pairs are such).

    >>> pts = np.array([[0.0, 0], [4, 0], [0, 3], [4, 3], [2, -1], [2, 1]])
    >>> piece_gaps(pts, np.array([0, 2, 4]), np.array([1, 3, 5]), np.array([0, 0]), np.array([1, 2])).tolist()
    [3.0, 0.0]
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    out = np.empty(len(p), dtype=np.float64)
    # A hair above each limit: rounding in a box's distance must never skip a pair of segments at the limit.
    bound = np.full(len(p), np.inf) if limit is None else np.asarray(limit, np.float64) * (1 + 1e-9) + 1e-9
    first, last = np.asarray(first, np.intp), np.asarray(last, np.intp)
    _piece_gaps(points, first, last, np.asarray(p), np.asarray(q), bound, out)
    return out


@njit(cache=True, nogil=True)
def _piece_gaps(pts, first, last, p, q, bound, out):  # pragma: no cover - compiled
    for k in range(len(p)):
        best = bound[k]
        a0, a1, b0, b1 = first[p[k]], last[p[k]], first[q[k]], last[q[k]]
        if best < np.inf:  # pieces whose boxes are apart by more than the bound: no segment of theirs is nearer
            ax0, ay0, ax1, ay1 = _box(pts, a0, a1)
            bx0, by0, bx1, by1 = _box(pts, b0, b1)
            dx = max(0.0, max(bx0 - ax1, ax0 - bx1))
            dy = max(0.0, max(by0 - ay1, ay0 - by1))
            if dx * dx + dy * dy > best * best:
                out[k] = best
                continue
        for i in range(a0, a1):
            sx0 = min(pts[i, 0], pts[i + 1, 0])
            sx1 = max(pts[i, 0], pts[i + 1, 0])
            sy0 = min(pts[i, 1], pts[i + 1, 1])
            sy1 = max(pts[i, 1], pts[i + 1, 1])
            for j in range(b0, b1):
                # A segment pair whose boxes are farther apart than the best so far cannot be nearer; skipping
                # it leaves the smallest distance as it is.
                dx = max(0.0, max(min(pts[j, 0], pts[j + 1, 0]) - sx1, sx0 - max(pts[j, 0], pts[j + 1, 0])))
                dy = max(0.0, max(min(pts[j, 1], pts[j + 1, 1]) - sy1, sy0 - max(pts[j, 1], pts[j + 1, 1])))
                if dx * dx + dy * dy > best * best:
                    continue
                ax, ay, bx, by = pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1]
                d = _segment_to_segment(ax, ay, bx, by, pts[j, 0], pts[j, 1], pts[j + 1, 0], pts[j + 1, 1])
                if d < best:
                    best = d
            if best == 0.0:
                break
        out[k] = best


@njit(cache=True, nogil=True)
def _point_to_segment(px, py, ax, ay, bx, by):  # pragma: no cover - compiled
    """Distance from P to segment AB: to the nearer end where P projects outside AB, else |cross| / |AB|."""
    if ax == bx and ay == by:
        return np.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay)
    r = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2
    if r <= 0.0:
        return np.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    if r >= 1.0:
        return np.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
    s = ((ay - py) * (bx - ax) - (ax - px) * (by - ay)) / len2
    return abs(s) * np.sqrt(len2)


@njit(cache=True, nogil=True)
def _segment_to_segment(ax, ay, bx, by, cx, cy, dx, dy):  # pragma: no cover - compiled
    """Distance between segments AB and CD: 0 where they intersect, else the smallest distance of an end point
    to the other segment."""
    if ax == bx and ay == by:
        return _point_to_segment(ax, ay, cx, cy, dx, dy)
    if cx == dx and cy == dy:
        return _point_to_segment(dx, dy, ax, ay, bx, by)
    apart = False
    if max(ax, bx) < min(cx, dx) or min(ax, bx) > max(cx, dx) or max(ay, by) < min(cy, dy) or min(ay, by) > max(cy, dy):
        apart = True
    else:
        denom = (bx - ax) * (dy - cy) - (by - ay) * (dx - cx)
        if denom == 0.0:
            apart = True
        else:
            r = ((ay - cy) * (dx - cx) - (ax - cx) * (dy - cy)) / denom
            s = ((ay - cy) * (bx - ax) - (ax - cx) * (by - ay)) / denom
            if r < 0.0 or r > 1.0 or s < 0.0 or s > 1.0:
                apart = True
    if not apart:
        return 0.0
    return min(
        _point_to_segment(ax, ay, cx, cy, dx, dy),
        min(
            _point_to_segment(bx, by, cx, cy, dx, dy),
            min(_point_to_segment(cx, cy, ax, ay, bx, by), _point_to_segment(dx, dy, ax, ay, bx, by)),
        ),
    )


#: Segments per chunk of :func:`lines_within`: chunks whose boxes are apart are skipped whole, so two long lines
#: cost about (n / 16) × (m / 16) box tests, not n × m distances.
WITHIN_CHUNK = 16


def lines_within(
    points: NDArray[np.float64],
    first: NDArray[np.intp],
    last: NDArray[np.intp],
    p: NDArray[np.intp],
    q: NDArray[np.intp],
    d: float,
) -> NDArray[np.bool_]:
    """Whether lines ``p[k]`` and ``q[k]`` of ``points`` (a line: the polyline of points first..last, at least
    two) come within ``d`` of each other, for every k: what ``shapely.dwithin`` decides for their linestrings.

    GEOS decides it from the same segment-to-segment distances (its facet distance), stopping at the first pair
    of segments no farther apart than ``d``; so does this, with each distance from :func:`_segment_to_segment`
    (shapely's own, bit for bit). Chunks and segments whose boxes are more than ``2 d`` apart are skipped: the
    margin keeps rounding in a box from ever skipping a pair GEOS would count. A line of one point repeated is
    that point here, as in GEOS's plain test; GEOS's prepared test answers for such lines vary with what the
    prepared line was asked before (no contour is one: ``ccs.check_contour`` refuses them).

    >>> pts = np.array([[0.0, 0], [4, 0], [0, 3], [4, 3], [2, 0.5], [2, 1]])
    >>> lines_within(pts, np.array([0, 2, 4]), np.array([1, 3, 5]), np.array([0, 0]), np.array([1, 2]), 0.5).tolist()
    [False, True]
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    out = np.empty(len(p), dtype=np.bool_)
    first, last = np.asarray(first, np.intp), np.asarray(last, np.intp)
    _lines_within(points, first, last, np.asarray(p, np.intp), np.asarray(q, np.intp), float(d), WITHIN_CHUNK, out)
    return out


@njit(cache=True, nogil=True)
def _lines_within(pts, first, last, p, q, d, chunk, out):  # pragma: no cover - compiled
    reach = 2.0 * d
    for k in range(len(p)):
        out[k] = _within(pts, first[p[k]], last[p[k]], first[q[k]], last[q[k]], d, reach, chunk)


@njit(cache=True, nogil=True)
def _box(pts, lo, hi):  # pragma: no cover - compiled
    """(minx, miny, maxx, maxy) of points lo..hi."""
    x0, y0, x1, y1 = pts[lo, 0], pts[lo, 1], pts[lo, 0], pts[lo, 1]
    for i in range(lo + 1, hi + 1):
        x0 = min(x0, pts[i, 0])
        y0 = min(y0, pts[i, 1])
        x1 = max(x1, pts[i, 0])
        y1 = max(y1, pts[i, 1])
    return x0, y0, x1, y1


@njit(cache=True, nogil=True)
def _apart(ax0, ay0, ax1, ay1, bx0, by0, bx1, by1, reach):  # pragma: no cover - compiled
    """Are two boxes more than ``reach`` apart along x or along y?"""
    return bx0 - ax1 > reach or ax0 - bx1 > reach or by0 - ay1 > reach or ay0 - by1 > reach


@njit(cache=True, nogil=True)
def _within(pts, a0, a1, b0, b1, d, reach, chunk):  # pragma: no cover - compiled
    """Does some segment of points a0..a1 lie within ``d`` of some segment of points b0..b1?"""
    ax0, ay0, ax1, ay1 = _box(pts, a0, a1)
    bx0, by0, bx1, by1 = _box(pts, b0, b1)
    if _apart(ax0, ay0, ax1, ay1, bx0, by0, bx1, by1, reach):
        return False
    nb = (b1 - b0 + chunk - 1) // chunk
    boxes = np.empty((nb, 4))
    for c in range(nb):
        boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3] = _box(pts, b0 + c * chunk, min(b0 + (c + 1) * chunk, b1))
    for ca in range(a0, a1, chunk):
        ce = min(ca + chunk, a1)
        cx0, cy0, cx1, cy1 = _box(pts, ca, ce)
        if _apart(cx0, cy0, cx1, cy1, bx0, by0, bx1, by1, reach):
            continue
        for c in range(nb):
            if _apart(cx0, cy0, cx1, cy1, boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3], reach):
                continue
            cb = b0 + c * chunk
            for i in range(ca, ce):
                sx0, sy0, sx1, sy1 = _box(pts, i, i + 1)
                for j in range(cb, min(cb + chunk, b1)):
                    tx0, ty0, tx1, ty1 = _box(pts, j, j + 1)
                    if _apart(sx0, sy0, sx1, sy1, tx0, ty0, tx1, ty1, reach):
                        continue
                    ax, ay, bx, by = pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1]
                    if _segment_to_segment(ax, ay, bx, by, pts[j, 0], pts[j, 1], pts[j + 1, 0], pts[j + 1, 1]) <= d:
                        return True
    return False
