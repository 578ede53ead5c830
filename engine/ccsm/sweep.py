"""Do two polylines meet while their vertices move? Exact contact of lines in linear motion.

Between two neighbouring scales of the ladder every contour's t is linear in log scale and every slice is
linear in t (docs/design.md section 4.8), so each vertex moves on a straight line at a constant pace, the
same pace for all contours. Two lines apart at the start that meet later meet first where a vertex of one
reaches a segment of the other. Along the motion (parameter ``lam`` in [0, 1]) the orientation of a vertex
against a segment is a quadratic in ``lam``; its roots in [0, 1] are the only moments the vertex can be on
the segment's line, and the vertex meets the segment at a root where it lies between the segment's ends.
Checking every vertex against every segment that can reach it therefore misses no contact.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Slack on the position along a segment (a share of its length) and on the discriminant (a share of the
#: linear term squared): rounding in a root must not let a contact at a segment's end, or a grazing touch
#: (a double root), slip through. Both far below anything a map could show.
CONTACT_SLACK = 1e-9


@njit(cache=True, nogil=True)
def motion_moments(c0, c1, c2, slack, roots):  # pragma: no cover - compiled
    """Moments lam worth testing for c0 + c1 lam + c2 lam^2 = 0: both ends and the real roots; returns how many."""
    # The ends of the motion themselves: a contact exactly at lam = 0 or 1 is a contact too.
    roots[0] = 0.0
    roots[1] = 1.0
    n = 2
    big = max(abs(c0), abs(c1), abs(c2))
    if big == 0.0:
        # The vertex stays on the segment's line throughout; with both ends, the middle decides.
        roots[n] = 0.5
        return n + 1
    if abs(c2) <= 1e-12 * big:
        if c1 != 0.0:
            roots[n] = -c0 / c1
            n += 1
        return n
    disc = c1 * c1 - 4.0 * c2 * c0
    if -slack * c1 * c1 < disc < 0.0:
        disc = 0.0  # a grazing touch (double root) must not be lost to rounding
    if disc < 0.0:
        return n
    sq = np.sqrt(disc)
    q = -0.5 * (c1 + sq) if c1 >= 0.0 else -0.5 * (c1 - sq)  # the numerically stable pair of roots
    if q == 0.0:
        roots[n] = 0.0
        return n + 1
    roots[n] = q / c2
    roots[n + 1] = c0 / q
    return n + 2


@njit(cache=True, nogil=True)
def _vertex_meets_segment(a, b, v, s, slack):  # pragma: no cover - compiled
    """Does vertex ``v`` lie on segment (s, s + 1) at some lam in [0, 1]? a, b: (N, 2) start and end points."""
    e0x = a[s + 1, 0] - a[s, 0]
    e0y = a[s + 1, 1] - a[s, 1]
    evx = (b[s + 1, 0] - b[s, 0]) - e0x
    evy = (b[s + 1, 1] - b[s, 1]) - e0y
    r0x = a[v, 0] - a[s, 0]
    r0y = a[v, 1] - a[s, 1]
    rvx = (b[v, 0] - b[s, 0]) - r0x
    rvy = (b[v, 1] - b[s, 1]) - r0y
    c0 = e0x * r0y - e0y * r0x
    c1 = e0x * rvy - e0y * rvx + evx * r0y - evy * r0x
    c2 = evx * rvy - evy * rvx
    roots = np.empty(5)
    n = motion_moments(c0, c1, c2, slack, roots)
    for k in range(n):
        lam = roots[k]
        if lam < 0.0 or lam > 1.0:
            continue
        ex = e0x + lam * evx
        ey = e0y + lam * evy
        rx = r0x + lam * rvx
        ry = r0y + lam * rvy
        ee = ex * ex + ey * ey
        rr = rx * rx + ry * ry
        if ee == 0.0:
            if rr == 0.0:
                return True
            continue
        # At a root the vertex is on the segment's line by construction; at the two ends of the motion
        # (k < 2) it must be checked, within rounding relative to the lengths involved.
        if k < 2 and abs(ex * ry - ey * rx) > 1e-9 * (ee + rr):
            continue
        along = (rx * ex + ry * ey) / ee
        if -slack <= along <= 1.0 + slack:
            return True
    return False


@njit(cache=True, nogil=True)
def _vertices_reach_segments(a, b, lo, hi, v0, v1, s0, s1, slack):  # pragma: no cover - compiled
    """Does any vertex v0..v1 meet any segment s0..s1-1? Boxes of each vertex's and segment's sweep first."""
    vx0 = lo[v0 : v1 + 1, 0].min()
    vy0 = lo[v0 : v1 + 1, 1].min()
    vx1 = hi[v0 : v1 + 1, 0].max()
    vy1 = hi[v0 : v1 + 1, 1].max()
    for s in range(s0, s1):
        sx0 = min(lo[s, 0], lo[s + 1, 0])
        sy0 = min(lo[s, 1], lo[s + 1, 1])
        sx1 = max(hi[s, 0], hi[s + 1, 0])
        sy1 = max(hi[s, 1], hi[s + 1, 1])
        if vx1 < sx0 or vx0 > sx1 or vy1 < sy0 or vy0 > sy1:
            continue  # the segment's sweep misses every vertex's sweep
        for v in range(v0, v1 + 1):
            if hi[v, 0] < sx0 or lo[v, 0] > sx1 or hi[v, 1] < sy0 or lo[v, 1] > sy1:
                continue
            if _vertex_meets_segment(a, b, v, s, slack):
                return True
    return False


@njit(cache=True, nogil=True)
def _pieces_meet(a, b, first, last, pp, qq, slack, out):  # pragma: no cover - compiled
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    for k in range(len(pp)):
        p = pp[k]
        q = qq[k]
        out[k] = _vertices_reach_segments(
            a, b, lo, hi, first[p], last[p], first[q], last[q], slack
        ) or _vertices_reach_segments(a, b, lo, hi, first[q], last[q], first[p], last[p], slack)


def pieces_meet(
    start: NDArray[np.float64],
    end: NDArray[np.float64],
    first: NDArray[np.intp],
    last: NDArray[np.intp],
    p: NDArray[np.intp],
    q: NDArray[np.intp],
) -> NDArray[np.bool_]:
    """For each pair of pieces (p[k], q[k]), whether they meet at some moment of the motion.

    Parameters
    ----------
    start, end
        (N, 2) float64 points of all lines concatenated, at the start and at the end of the motion (metres).
    first, last
        (P,) index of each piece's first and last point in ``start``/``end``.
    p, q
        (K,) indices of the pieces to compare.

    Returns
    -------
    (K,) bool
    """
    out = np.zeros(len(p), dtype=np.bool_)
    if len(p):
        _pieces_meet(
            np.ascontiguousarray(start, dtype=np.float64),
            np.ascontiguousarray(end, dtype=np.float64),
            first.astype(np.int64),
            last.astype(np.int64),
            p.astype(np.int64),
            q.astype(np.int64),
            CONTACT_SLACK,
            out,
        )
    return out
