"""Which contours of a morph tile cross properly at some fraction of the level? One compiled pass, exact.

A client draws a contour at fraction ``f`` as ``start + w(f) (end - start)`` with ``w`` piecewise linear in ``f``
between the level's nine steps (docs/morph-tiles.md), so inside a step every vertex moves on a straight line at a
constant pace: at the step's moment ``lam`` in [0, 1] it is at ``P_k + lam (P_k+1 - P_k)``.

The argument (docs/design.md section 4.8). The orientation of a point against a segment, the cross product
``(q2 - q1) x (p - q1)``, is then a quadratic in ``lam``. Two segments cross *properly* exactly when both ends of
each lie strictly on opposite sides of the other: a strict sign condition on four such quadratics. Between two
consecutive roots of the four no sign changes, so the condition holds on the whole of such an interval or nowhere
in it; and because it is strict, where it holds at a root or at an end of the step it holds on a neighbouring
interval too. Testing it at ``lam`` = 0, 1 and at the middle of every interval between consecutive moments of
{0, the roots inside (0, 1), 1} therefore finds a proper crossing at any moment of the step, not only at the frames
a client happens to draw. It is exact up to floating-point rounding of the roots and of the signs, far below a
tile unit. Touching (an orientation of zero) is not a crossing: on the grid, lines closer than a unit may be
forced to touch.

Only pairs of pieces (PIECE_SEGMENTS segments of a part) of different contours whose boxes over the whole level
overlap are compared, and inside them only segments whose boxes over the step overlap.
"""

from __future__ import annotations

import numpy as np
import shapely
from numba import njit
from numpy.typing import NDArray

#: Segments per piece: the box index sees pieces, the compiled pass compares their segments pair by pair.
PIECE_SEGMENTS = 12
#: Below this share of the largest coefficient the lam^2 term is dropped (the other root is far outside [0, 1]).
LINEAR_SHARE = 1e-12


@njit(cache=True, nogil=True, inline="always")
def _side(ax, ay, bx, by, cx, cy):  # pragma: no cover - compiled
    """Sign of the turn a -> b -> c: 1 left, -1 right, 0 on one line."""
    d = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (d > 0.0) - (d < 0.0)


@njit(cache=True, nogil=True)
def _add_roots(a, d, s, v, roots, n):  # pragma: no cover - compiled
    """Append to ``roots[n:]`` the moments inside (0, 1) where point v is on the line of segment (s, s + 1);
    points move as ``a + lam d``. Returns the new count."""
    e0x, e0y = a[s + 1, 0] - a[s, 0], a[s + 1, 1] - a[s, 1]
    evx, evy = d[s + 1, 0] - d[s, 0], d[s + 1, 1] - d[s, 1]
    r0x, r0y = a[v, 0] - a[s, 0], a[v, 1] - a[s, 1]
    rvx, rvy = d[v, 0] - d[s, 0], d[v, 1] - d[s, 1]
    c0 = e0x * r0y - e0y * r0x
    c1 = e0x * rvy - e0y * rvx + evx * r0y - evy * r0x
    c2 = evx * rvy - evy * rvx
    big = max(abs(c0), abs(c1), abs(c2))
    if big == 0.0:
        return n  # always on the line: that side test never holds strictly, it splits nothing
    if abs(c2) <= LINEAR_SHARE * big:
        if c1 != 0.0 and 0.0 < -c0 / c1 < 1.0:
            roots[n] = -c0 / c1
            n += 1
        return n
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc < 0.0:
        return n  # one sign all step long
    sq = np.sqrt(disc)
    q = -0.5 * (c1 + sq) if c1 >= 0.0 else -0.5 * (c1 - sq)  # the numerically stable pair of roots
    for r in (q / c2, c0 / q if q != 0.0 else 0.0):
        if 0.0 < r < 1.0:
            roots[n] = r
            n += 1
    return n


@njit(cache=True, nogil=True)
def _cross_properly_at(a, d, s, t, lam):  # pragma: no cover - compiled
    """Do segments (s, s + 1) and (t, t + 1) cross properly at moment ``lam``?"""
    p1x, p1y = a[s, 0] + lam * d[s, 0], a[s, 1] + lam * d[s, 1]
    p2x, p2y = a[s + 1, 0] + lam * d[s + 1, 0], a[s + 1, 1] + lam * d[s + 1, 1]
    q1x, q1y = a[t, 0] + lam * d[t, 0], a[t, 1] + lam * d[t, 1]
    q2x, q2y = a[t + 1, 0] + lam * d[t + 1, 0], a[t + 1, 1] + lam * d[t + 1, 1]
    if _side(p1x, p1y, p2x, p2y, q1x, q1y) * _side(p1x, p1y, p2x, p2y, q2x, q2y) >= 0:
        return False
    return _side(q1x, q1y, q2x, q2y, p1x, p1y) * _side(q1x, q1y, q2x, q2y, p2x, p2y) < 0


@njit(cache=True, nogil=True)
def _segments_cross_in_step(a, d, s, t, roots):  # pragma: no cover - compiled
    """Do segments (s, s + 1) and (t, t + 1) cross properly at some moment of the step (module docstring)?"""
    roots[0] = 0.0
    roots[1] = 1.0
    n = _add_roots(a, d, s, t, roots, 2)
    n = _add_roots(a, d, s, t + 1, roots, n)
    n = _add_roots(a, d, t, s, roots, n)
    n = _add_roots(a, d, t, s + 1, roots, n)
    moments = np.sort(roots[:n])
    if _cross_properly_at(a, d, s, t, 0.0) or _cross_properly_at(a, d, s, t, 1.0):
        return True
    for i in range(n - 1):
        if _cross_properly_at(a, d, s, t, 0.5 * (moments[i] + moments[i + 1])):
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _apart(lo, hi, i, j):  # pragma: no cover - compiled
    """Are boxes i and j (rows of lo, hi) apart?"""
    return hi[i, 0] < lo[j, 0] or hi[j, 0] < lo[i, 0] or hi[i, 1] < lo[j, 1] or hi[j, 1] < lo[i, 1]


@njit(cache=True, nogil=True)
def _pieces_cross_in_step(a, d, lo, hi, p0, p1, q0, q1, roots):  # pragma: no cover - compiled
    """Does a segment of points p0..p1 cross one of points q0..q1 properly in the step? lo, hi: each segment's
    box over the step (row s for segment (s, s + 1))."""
    for s in range(p0, p1):
        for t in range(q0, q1):
            if not _apart(lo, hi, s, t) and _segments_cross_in_step(a, d, s, t, roots):
                return True
    return False


@njit(cache=True, nogil=True)
def _pairs_cross(pos, first, last, pp, qq, out):  # pragma: no cover - compiled
    """out[k]: do pieces pp[k] and qq[k] cross properly at some moment of the level? pos: (steps + 1, N, 2)."""
    roots = np.empty(10)
    n = pos.shape[1]
    for k in range(pos.shape[0] - 1):
        a = pos[k]
        d = pos[k + 1] - a
        # Box of each segment (s, s + 1) over the step, in row s: its ends at both moments bound its motion.
        ends_lo = np.minimum(a, pos[k + 1])
        ends_hi = np.maximum(a, pos[k + 1])
        lo = np.empty((n, 2))
        hi = np.empty((n, 2))
        lo[: n - 1] = np.minimum(ends_lo[:-1], ends_lo[1:])
        hi[: n - 1] = np.maximum(ends_hi[:-1], ends_hi[1:])
        lo[n - 1] = ends_lo[n - 1]
        hi[n - 1] = ends_hi[n - 1]
        for m in range(len(pp)):
            if out[m]:
                continue
            p, q = pp[m], qq[m]
            out[m] = _pieces_cross_in_step(a, d, lo, hi, first[p], last[p], first[q], last[q], roots)


def _pieces(part_len: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Pieces of at most PIECE_SEGMENTS segments of each part of two points or more: first and last point
    (neighbouring pieces share one), and the part."""
    starts = np.cumsum(part_len) - part_len
    usable = np.flatnonzero(part_len >= 2)
    segments = part_len[usable] - 1
    per_part = (segments - 1) // PIECE_SEGMENTS + 1
    part = np.repeat(usable, per_part)
    k = np.arange(per_part.sum()) - np.repeat(np.cumsum(per_part) - per_part, per_part)
    first = starts[part] + k * PIECE_SEGMENTS
    last = np.minimum(first + PIECE_SEGMENTS, starts[part] + part_len[part] - 1)
    return first.astype(np.int64), last.astype(np.int64), part.astype(np.int64)


def morph_crossing_pairs(
    start: NDArray[np.int64],
    end: NDArray[np.int64],
    part_len: NDArray[np.int64],
    part_owner: NDArray[np.int64],
    w: NDArray[np.float64],
    skip: NDArray[np.bool_] | None = None,
) -> set[tuple[int, int]]:
    """Pairs (a, b), a < b, of contours that cross properly at some fraction of the level, as a client draws them.

    Parameters
    ----------
    start, end
        (N, 2) grid points of every part at the start and at the end of the level, parts concatenated.
    part_len, part_owner
        (P,) points of each part, and the contour (a column of ``w``) it belongs to.
    w
        (steps + 1, n) weight of the end geometry per contour at the steps (piecewise linear between them).
    skip
        (n,) contours whose pairs with one another need no check (both held still, snap-rounded together).

    >>> a = np.array([[0, 0], [10, 0]]); b0, b1 = np.array([[4, 1], [6, 1]]), np.array([[4, -1], [6, -1]])
    >>> w = np.array([[0.0, 0.0], [0.0, 0.5], [0.0, 1.0]])  # b sinks through a in the first step
    >>> parts = (np.array([2, 2]), np.array([0, 1]))
    >>> morph_crossing_pairs(np.vstack([a, b0]), np.vstack([a, b1]), *parts, w)  # a T at most: never proper
    set()
    >>> b1 = np.array([[4, -1], [6, 3]])  # b tilts as it sinks: its left end passes below a
    >>> morph_crossing_pairs(np.vstack([a, b0]), np.vstack([a, b1]), *parts, w)
    {(0, 1)}
    """
    first, last, piece_part = _pieces(np.asarray(part_len, dtype=np.int64))
    if len(first) < 2:
        return set()
    s = np.asarray(start, dtype=np.float64)
    e = np.asarray(end, dtype=np.float64)
    point_owner = np.repeat(np.asarray(part_owner, dtype=np.int64), part_len)
    pos = np.ascontiguousarray(s[None] + w[:, point_owner][..., None] * (e - s)[None])  # (steps + 1, N, 2)
    # Each piece's box over the whole level: the motion between steps is straight, so the steps bound it.
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    box_lo = np.minimum(np.minimum.reduceat(lo, first), lo[last])
    box_hi = np.maximum(np.maximum.reduceat(hi, first), hi[last])
    boxes = shapely.box(box_lo[:, 0], box_lo[:, 1], box_hi[:, 0], box_hi[:, 1])
    p, q = shapely.STRtree(boxes).query(boxes)
    owner = np.asarray(part_owner, dtype=np.int64)[piece_part]
    keep = owner[p] < owner[q]  # different contours, each pair of pieces once
    if skip is not None:
        keep &= ~(skip[owner[p]] & skip[owner[q]])
    p, q = p[keep].astype(np.int64), q[keep].astype(np.int64)
    hit = np.zeros(len(p), dtype=np.bool_)
    _pairs_cross(pos, first, last, p, q, hit)
    return {(int(x), int(y)) for x, y in zip(owner[p[hit]].tolist(), owner[q[hit]].tolist(), strict=True)}
