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


@njit(cache=True, nogil=True)
def _slices_of_piece(base, top, first, last, t0, t1, a, b, lo, hi, at):  # pragma: no cover - compiled
    """Points first..last of a piece at t0 and t1 into a, b (from row ``at``), as ``base + t (top - base)``;
    returns the piece's box over the motion: min and max x, y of lo = min(a, b), hi = max(a, b)."""
    bx0 = np.inf
    by0 = np.inf
    bx1 = -np.inf
    by1 = -np.inf
    for i in range(first, last + 1):
        j = at + i - first
        for d in range(2):
            step = top[i, d] - base[i, d]
            a[j, d] = base[i, d] + t0 * step
            b[j, d] = base[i, d] + t1 * step
            lo[j, d] = min(a[j, d], b[j, d])
            hi[j, d] = max(a[j, d], b[j, d])
        bx0 = min(bx0, lo[j, 0])
        by0 = min(by0, lo[j, 1])
        bx1 = max(bx1, hi[j, 0])
        by1 = max(by1, hi[j, 1])
    return bx0, by0, bx1, by1


@njit(cache=True, nogil=True)
def _pairs_meet_in_steps(
    base, top, first, last, owner, pp, qq, gap, reach, t0, t1, shown, touch, slack, out
):  # pragma: no cover - compiled
    """out[k]: do pieces pp[k] and qq[k] meet in some step s (lines i moving from t0[i, s] to t1[i, s])?

    Pairs come sorted by their lines; once a pair of lines meets, their other pairs of pieces are skipped.
    """
    size = 0
    for k in range(len(first)):
        size = max(size, last[k] - first[k] + 1)
    a = np.empty((2 * size, 2))
    b = np.empty((2 * size, 2))
    lo = np.empty((2 * size, 2))
    hi = np.empty((2 * size, 2))
    met = False
    for k in range(len(pp)):
        p = pp[k]
        q = qq[k]
        i = owner[p]
        j = owner[q]
        if k > 0 and met and owner[pp[k - 1]] == i and owner[qq[k - 1]] == j:
            continue  # these two lines already meet
        met = False
        np_ = last[p] - first[p] + 1
        nq = last[q] - first[q] + 1
        for s in range(t0.shape[1]):
            if not (shown[i, s] and shown[j, s]):
                continue
            # A slice at t is within |t| * reach of the base row: farther apart than that, they cannot meet.
            most_i = max(abs(t0[i, s]), abs(t1[i, s]))
            most_j = max(abs(t0[j, s]), abs(t1[j, s]))
            if not gap[k] <= most_i * reach[p] + most_j * reach[q] + touch:
                continue
            px0, py0, px1, py1 = _slices_of_piece(base, top, first[p], last[p], t0[i, s], t1[i, s], a, b, lo, hi, 0)
            qx0, qy0, qx1, qy1 = _slices_of_piece(base, top, first[q], last[q], t0[j, s], t1[j, s], a, b, lo, hi, np_)
            if px0 > qx1 or qx0 > px1 or py0 > qy1 or qy0 > py1:
                continue  # their boxes over this motion miss each other
            end = np_ + nq - 1
            if _vertices_reach_segments(a, b, lo, hi, 0, np_ - 1, np_, end, slack) or _vertices_reach_segments(
                a, b, lo, hi, np_, end, 0, np_ - 1, slack
            ):
                met = True
                break
        out[k] = met


def pairs_meet_in_steps(
    base: NDArray[np.float64],
    top: NDArray[np.float64],
    first: NDArray[np.intp],
    last: NDArray[np.intp],
    owner: NDArray[np.intp],
    pairs: tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]],
    t0: NDArray[np.float64],
    t1: NDArray[np.float64],
    shown: NDArray[np.bool_],
    touch: float,
) -> NDArray[np.bool_]:
    """For each pair of pieces, whether they meet in any of S steps of the motion, each line i moving from its
    slice at ``t0[i, s]`` to its slice at ``t1[i, s]`` in step s, if ``shown[i, s]``.

    Parameters
    ----------
    base, top
        (N, 2) float64 points of all pieces at t = 0 and t = 1 (metres); a slice at t is ``base + t (top - base)``.
    first, last, owner
        (P,) each piece's first and last point, and its line.
    pairs
        (p, q, gap, reach): (K,) pieces of each pair, sorted by their lines (p's, then q's), their distance
        at t = 0, and (P,) each piece's largest move from t = 0 to t = 1.
    t0, t1, shown
        (lines, S) each line's t at both ends of each step, and whether it is shown in it.
    touch
        Slack on the distance test, metres: pairs that far apart at the limit are kept.

    Returns
    -------
    (K,) bool; a pair of pieces whose lines are already found to meet by an earlier pair may be left False.
    """
    p, q, gap, reach = pairs
    out = np.zeros(len(p), dtype=np.bool_)
    if len(p):
        _pairs_meet_in_steps(
            np.ascontiguousarray(base, dtype=np.float64),
            np.ascontiguousarray(top, dtype=np.float64),
            first.astype(np.int64),
            last.astype(np.int64),
            owner.astype(np.int64),
            p.astype(np.int64),
            q.astype(np.int64),
            np.ascontiguousarray(gap, dtype=np.float64),
            np.ascontiguousarray(reach, dtype=np.float64),
            np.ascontiguousarray(t0, dtype=np.float64),
            np.ascontiguousarray(t1, dtype=np.float64),
            np.ascontiguousarray(shown, dtype=np.bool_),
            float(touch),
            CONTACT_SLACK,
            out,
        )
    return out
