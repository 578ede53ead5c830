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
overlap are compared (found with a uniform grid, as in ``engine.tiles.crossings``); inside them, a pair of
segments only if at the start they are no farther apart than their points travel in the level, and in a step
only if their boxes over the step overlap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.ccsm.sweep import motion_moments
from engine.ccsm.topology import piece_ranges
from engine.tiles.crossings import orientation_sign
from engine.tiles.runs import ranges

#: Segments per piece: the grid sees pieces, the compiled pass compares their segments pair by pair (4 was
#: fastest on the sample's densest morph tile, against 2, 3, 5, 6 and 12).
PIECE_SEGMENTS = 4
#: Grid units per side of a cell of the grid of pieces: a few pieces per cell on the densest tiles.
CELL_UNITS = 32.0


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
    moments = np.empty(4)
    # The roots of the repair's sweep (no slack: a double root is a touch, which splits nothing here).
    for r in moments[: motion_moments(c0, c1, c2, 0.0, moments)]:
        if 0.0 < r < 1.0:
            roots[n] = r
            n += 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _cross_properly(p1x, p1y, p2x, p2y, q1x, q1y, q2x, q2y):  # pragma: no cover - compiled
    """Do segments p1-p2 and q1-q2 cross at a point inside both?"""
    if orientation_sign(p1x, p1y, p2x, p2y, q1x, q1y) * orientation_sign(p1x, p1y, p2x, p2y, q2x, q2y) >= 0:
        return False
    return orientation_sign(q1x, q1y, q2x, q2y, p1x, p1y) * orientation_sign(q1x, q1y, q2x, q2y, p2x, p2y) < 0


@njit(cache=True, nogil=True)
def _cross_properly_at(a, d, s, t, lam):  # pragma: no cover - compiled
    """Do segments (s, s + 1) and (t, t + 1) cross properly at moment ``lam``?"""
    p1x, p1y = a[s, 0] + lam * d[s, 0], a[s, 1] + lam * d[s, 1]
    p2x, p2y = a[s + 1, 0] + lam * d[s + 1, 0], a[s + 1, 1] + lam * d[s + 1, 1]
    q1x, q1y = a[t, 0] + lam * d[t, 0], a[t, 1] + lam * d[t, 1]
    q2x, q2y = a[t + 1, 0] + lam * d[t + 1, 0], a[t + 1, 1] + lam * d[t + 1, 1]
    return _cross_properly(p1x, p1y, p2x, p2y, q1x, q1y, q2x, q2y)


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


@njit(cache=True, nogil=True)
def _point_segment_dist2(px, py, ax, ay, bx, by):  # pragma: no cover - compiled
    """Squared distance from point p to segment a-b."""
    ex, ey = bx - ax, by - ay
    ee = ex * ex + ey * ey
    u = 0.0 if ee == 0.0 else min(1.0, max(0.0, ((px - ax) * ex + (py - ay) * ey) / ee))
    dx, dy = ax + u * ex - px, ay + u * ey - py
    return dx * dx + dy * dy


@njit(cache=True, nogil=True)
def _segments_dist(a, s, t):  # pragma: no cover - compiled
    """Distance between segments (s, s + 1) and (t, t + 1) of points ``a``; 0 when they meet."""
    p1x, p1y, p2x, p2y = a[s, 0], a[s, 1], a[s + 1, 0], a[s + 1, 1]
    q1x, q1y, q2x, q2y = a[t, 0], a[t, 1], a[t + 1, 0], a[t + 1, 1]
    if _cross_properly(p1x, p1y, p2x, p2y, q1x, q1y, q2x, q2y):
        return 0.0
    d = min(
        _point_segment_dist2(q1x, q1y, p1x, p1y, p2x, p2y),
        _point_segment_dist2(q2x, q2y, p1x, p1y, p2x, p2y),
        _point_segment_dist2(p1x, p1y, q1x, q1y, q2x, q2y),
        _point_segment_dist2(p2x, p2y, q1x, q1y, q2x, q2y),
    )
    return np.sqrt(d)


@njit(cache=True, nogil=True)
def _may_meet(pos, lo, hi, reach, s, t):  # pragma: no cover - compiled
    """Can segments (s, s + 1) and (t, t + 1) meet at all in the level? Their boxes over the level must overlap,
    and at the start they must be no farther apart than the farthest their points travel from there."""
    if (
        max(hi[s, 0], hi[s + 1, 0]) < min(lo[t, 0], lo[t + 1, 0])
        or max(hi[t, 0], hi[t + 1, 0]) < min(lo[s, 0], lo[s + 1, 0])
        or max(hi[s, 1], hi[s + 1, 1]) < min(lo[t, 1], lo[t + 1, 1])
        or max(hi[t, 1], hi[t + 1, 1]) < min(lo[s, 1], lo[s + 1, 1])
    ):
        return False
    # Each point of a segment is a mix of its ends, so it stays within the ends' farthest travel of the segment
    # at the start; the margin covers rounding.
    travel = max(reach[s], reach[s + 1]) + max(reach[t], reach[t + 1])
    return _segments_dist(pos[0], s, t) <= travel * (1.0 + 1e-9) + 1e-9


@njit(cache=True, nogil=True)
def _step_apart(a, b, s, t):  # pragma: no cover - compiled
    """Are the boxes of segments (s, s + 1) and (t, t + 1) over a step (points a at its start, b at its end) apart?"""
    for c in range(2):
        s_lo = min(a[s, c], a[s + 1, c], b[s, c], b[s + 1, c])
        s_hi = max(a[s, c], a[s + 1, c], b[s, c], b[s + 1, c])
        t_lo = min(a[t, c], a[t + 1, c], b[t, c], b[t + 1, c])
        t_hi = max(a[t, c], a[t + 1, c], b[t, c], b[t + 1, c])
        if s_hi < t_lo or t_hi < s_lo:
            return True
    return False


@njit(cache=True, nogil=True)
def _segments_cross_in_level(pos, steps_d, s, t, roots):  # pragma: no cover - compiled
    """Do segments (s, s + 1) and (t, t + 1) cross properly at some moment of some step of the level?"""
    for k in range(pos.shape[0] - 1):
        if not _step_apart(pos[k], pos[k + 1], s, t) and _segments_cross_in_step(pos[k], steps_d[k], s, t, roots):
            return True
    return False


@njit(cache=True, nogil=True)
def _travel(pos):  # pragma: no cover - compiled
    """Each point's box over the level (lo, hi: (N, 2)) and its farthest distance from its place at the start."""
    lo = pos[0].copy()
    hi = pos[0].copy()
    reach = np.zeros(pos.shape[1])
    for k in range(1, pos.shape[0]):
        for v in range(pos.shape[1]):
            for c in range(2):
                lo[v, c] = min(lo[v, c], pos[k, v, c])
                hi[v, c] = max(hi[v, c], pos[k, v, c])
            dx, dy = pos[k, v, 0] - pos[0, v, 0], pos[k, v, 1] - pos[0, v, 1]
            reach[v] = max(reach[v], np.sqrt(dx * dx + dy * dy))
    return lo, hi, reach


@njit(cache=True, nogil=True)
def _pieces_cross(pos, steps_d, lo, hi, reach, p0, p1, q0, q1, roots):  # pragma: no cover - compiled
    """Does a segment of points p0..p1 cross one of points q0..q1 properly at some moment of the level?"""
    for s in range(p0, p1):
        for t in range(q0, q1):
            if _may_meet(pos, lo, hi, reach, s, t) and _segments_cross_in_level(pos, steps_d, s, t, roots):
                return True
    return False


@njit(cache=True, nogil=True)
def _crossing_pieces(pos, first, last, boxes, owner, skip):  # noqa: C901  # pragma: no cover - compiled
    """Pieces of different contours that cross properly at some moment of the level: (M, 2) their owners, a row
    per pair of pieces.

    Pieces go into the cells of a uniform grid their boxes over the level cover; two pieces are compared in
    one cell only, the one holding the lower-left corner of where their boxes overlap.
    """
    steps_d = pos[1:] - pos[:-1]
    lo, hi, reach = _travel(pos)
    x0, y0 = boxes[:, 0].min(), boxes[:, 1].min()
    cell = max(CELL_UNITS, 1e-9)
    nx = int((boxes[:, 2].max() - x0) // cell) + 1
    ny = int((boxes[:, 3].max() - y0) // cell) + 1
    n = len(first)
    cx0 = np.empty(n, np.int64)
    cx1 = np.empty(n, np.int64)
    cy0 = np.empty(n, np.int64)
    cy1 = np.empty(n, np.int64)
    counts = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        cx0[i] = int((boxes[i, 0] - x0) // cell)
        cx1[i] = int((boxes[i, 2] - x0) // cell)
        cy0[i] = int((boxes[i, 1] - y0) // cell)
        cy1[i] = int((boxes[i, 3] - y0) // cell)
        for cy in range(cy0[i], cy1[i] + 1):
            for cx in range(cx0[i], cx1[i] + 1):
                counts[cy * nx + cx + 1] += 1
    offsets = np.cumsum(counts)
    fill = offsets.copy()
    members = np.empty(offsets[-1], np.int64)
    for i in range(n):
        for cy in range(cy0[i], cy1[i] + 1):
            for cx in range(cx0[i], cx1[i] + 1):
                members[fill[cy * nx + cx]] = i
                fill[cy * nx + cx] += 1
    roots = np.empty(10)
    found = np.empty((64, 2), np.int64)
    n_found = 0
    for c in range(nx * ny):
        for u in range(offsets[c], offsets[c + 1]):
            for v in range(u + 1, offsets[c + 1]):
                i, j = members[u], members[v]
                if owner[i] == owner[j] or (skip[owner[i]] and skip[owner[j]]):
                    continue
                if boxes[i, 2] < boxes[j, 0] or boxes[j, 2] < boxes[i, 0]:
                    continue
                if boxes[i, 3] < boxes[j, 1] or boxes[j, 3] < boxes[i, 1]:
                    continue
                if max(cy0[i], cy0[j]) * nx + max(cx0[i], cx0[j]) != c:
                    continue  # compared in another cell
                if _pieces_cross(pos, steps_d, lo, hi, reach, first[i], last[i], first[j], last[j], roots):
                    if n_found == len(found):
                        found = np.concatenate((found, np.empty_like(found)))
                    found[n_found, 0] = owner[i]
                    found[n_found, 1] = owner[j]
                    n_found += 1
    return found[:n_found]


@njit(cache=True, nogil=True)
def _positions(start, end, w, point_owner):  # pragma: no cover - compiled
    """(steps + 1, N, 2) every point at every step: ``start + w (end - start)`` with its contour's ``w``."""
    pos = np.empty((w.shape[0], len(start), 2))
    for k in range(w.shape[0]):
        for v in range(len(start)):
            wk = w[k, point_owner[v]]
            for c in range(2):
                pos[k, v, c] = start[v, c] + wk * (end[v, c] - start[v, c])
    return pos


@njit(cache=True, nogil=True)
def _piece_boxes(pos, first, last):  # pragma: no cover - compiled
    """(P, 4) box of each piece's points over every step: min x, min y, max x, max y."""
    boxes = np.empty((len(first), 4))
    for i in range(len(first)):
        boxes[i, 0] = boxes[i, 1] = np.inf
        boxes[i, 2] = boxes[i, 3] = -np.inf
        for k in range(pos.shape[0]):
            for v in range(first[i], last[i] + 1):
                for c in range(2):
                    boxes[i, c] = min(boxes[i, c], pos[k, v, c])
                    boxes[i, 2 + c] = max(boxes[i, 2 + c], pos[k, v, c])
    return boxes


@dataclass(frozen=True)
class MorphParts:
    """The parts of a morph tile's contours: points at the start and the end of the level (same shape, grid
    units), points per part, and the contour (0..n-1) each part belongs to, parts grouped by contour."""

    start: NDArray[np.int64]
    end: NDArray[np.int64]
    part_len: NDArray[np.int64]
    part_owner: NDArray[np.int64]

    def of_owners(self, keep: NDArray[np.bool_]) -> MorphParts:
        """The parts of the contours with ``keep[owner]`` true."""
        chosen = keep[self.part_owner]
        point_chosen = np.repeat(chosen, self.part_len)
        return MorphParts(
            self.start[point_chosen], self.end[point_chosen], self.part_len[chosen], self.part_owner[chosen]
        )

    @staticmethod
    def joined(a: MorphParts, b: MorphParts) -> MorphParts:
        """The parts of both, grouped by contour again (a contour's parts keep their order)."""
        owner = np.concatenate([a.part_owner, b.part_owner])
        lens = np.concatenate([a.part_len, b.part_len])
        starts = np.cumsum(lens) - lens
        order = np.argsort(owner, kind="stable")
        start_pts, end_pts = np.concatenate([a.start, b.start]), np.concatenate([a.end, b.end])
        take = ranges(starts[order], starts[order] + lens[order])
        return MorphParts(start_pts[take], end_pts[take], lens[order], owner[order])


def morph_crossing_pairs(
    parts: MorphParts, w: NDArray[np.float64], skip: NDArray[np.bool_] | None = None
) -> set[tuple[int, int]]:
    """Pairs (a, b), a < b, of contours that cross properly at some fraction of the level, as a client draws them.

    Parameters
    ----------
    parts
        The contours' parts at the start and at the end of the level; a part's owner is a column of ``w``.
    w
        (steps + 1, n) weight of the end geometry per contour at the steps (piecewise linear between them).
    skip
        (n,) contours whose pairs with one another need no check (both held still, snap-rounded together).

    >>> a = np.array([[0, 0], [10, 0]]); b0, b1 = np.array([[4, 1], [6, 1]]), np.array([[4, -1], [6, -1]])
    >>> w = np.array([[0.0, 0.0], [0.0, 0.5], [0.0, 1.0]])  # b sinks through a in the first step
    >>> lens, owner = np.array([2, 2]), np.array([0, 1])
    >>> morph_crossing_pairs(MorphParts(np.vstack([a, b0]), np.vstack([a, b1]), lens, owner), w)  # a T at most
    set()
    >>> b1 = np.array([[4, -1], [6, 3]])  # b tilts as it sinks: its left end passes below a
    >>> morph_crossing_pairs(MorphParts(np.vstack([a, b0]), np.vstack([a, b1]), lens, owner), w)
    {(0, 1)}
    """
    start, end, part_len, part_owner = parts.start, parts.end, parts.part_len, parts.part_owner
    first, last, piece_part = (a.astype(np.int64) for a in piece_ranges(part_len, PIECE_SEGMENTS))
    if len(first) < 2:
        return set()
    point_owner = np.repeat(np.asarray(part_owner, dtype=np.int64), part_len)
    pos = _positions(
        np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64), np.ascontiguousarray(w), point_owner
    )
    # Each piece's box over the whole level: the motion between steps is straight, so the steps bound it.
    boxes = _piece_boxes(pos, first, last)
    owner = np.asarray(part_owner, dtype=np.int64)[piece_part]
    held = np.zeros(w.shape[1], dtype=np.bool_) if skip is None else np.asarray(skip, dtype=np.bool_)
    pairs = np.sort(_crossing_pieces(pos, first, last, boxes, owner, held), axis=1)
    return {(int(a), int(b)) for a, b in pairs.tolist()}
