"""Crossings between different contours (docs/design.md section 5: contours must never cross at any t).

Lines are cut into short pieces before they go into the spatial index: a 200 km contour has a bounding box
that overlaps everything, its pieces do not, so the index rejects almost every candidate pair cheaply.
"""

from __future__ import annotations

from collections.abc import Callable, Container, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.ccsm.near import box_pairs, lines_within, piece_gaps
from engine.ccsm.sweep import pairs_meet_in_steps, pieces_meet
from engine.types import Coords

if TYPE_CHECKING:
    from engine.ccsm.ccs import CCS


class SurfaceRows(Protocol):
    """What the contact check reads of a surface: its rows, its t at each ladder scale and the scale it vanishes
    at. A CCS is one; so is a stretch of its rows (``blocks.NearStretch``)."""

    @property
    def base(self) -> Coords:
        """(M, 2) rows at t = 0."""

    @property
    def top(self) -> Coords:
        """(M, 2) rows at t = 1."""

    @property
    def t_at_scale(self) -> NDArray[np.float64]:
        """(S,) t at each scale of the ladder."""

    @property
    def vanish_scale(self) -> float:
        """Scale denominator from which it is not shown (inf: never)."""


#: Threads for the crossing checks: the compiled pass releases the GIL, so two share the pairs of pieces.
CHECK_THREADS = 2

#: Input lines closer than this, metres, already touch: a surface's base row reproduces L0 only to about
#: 1e-7 m (docs/design.md section 3), so contours a few 1e-10 m apart in the input (lines of one level at a
#: saddle) would otherwise count as "apart" and their slices' rounding-level contacts as new crossings.
INPUT_TOUCH_M = 1e-6

#: Segments per indexed piece: small boxes for the index, few enough pieces to keep the query cheap.
PIECE_SEGMENTS = 24
#: Segments per piece in :func:`sweep_contacts`: the exact test compares every vertex of one piece with
#: every segment of the other, so its pieces are shorter (12 was fastest on the sample, against 6 and 24).
SWEEP_PIECE_SEGMENTS = 12


def _pieces(lines: Sequence[Coords]) -> tuple[NDArray[np.object_], NDArray[np.intp]]:
    """Cut every line into pieces of at most PIECE_SEGMENTS segments (neighbouring pieces share a vertex): their
    linestrings and their lines."""
    first, last, owner = _piece_ranges(lines, PIECE_SEGMENTS)
    if len(first) == 0:
        return np.empty(0, dtype=object), owner
    points, counts = _points_of(first, last)
    coords = _stacked([np.reshape(line, (-1, 2)) for line in lines])
    geoms = shapely.linestrings(coords[points], indices=np.repeat(np.arange(len(first)), counts))
    return geoms, owner


def crossing_pairs(lines: Sequence[Coords], only: set[int] | None = None, within: float = 0.0) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of different lines that intersect (cross or touch).

    Parameters
    ----------
    lines
        Polylines as (n, 2) arrays (a ring as a closed path), all in one CRS.
    only
        If given, only pairs that involve one of these line indices are looked for.
    within
        Also count lines closer than this (metres) as meeting (``INPUT_TOUCH_M`` for the input's own touches).
    """
    geoms, owner = _pieces(lines)
    if len(geoms) == 0:
        return set()
    tree = shapely.STRtree(geoms)
    probes = np.arange(len(geoms)) if only is None else np.flatnonzero(np.isin(owner, list(only)))
    boxes = geoms[probes] if within <= 0 else shapely.buffer(shapely.envelope(geoms[probes]), within)
    a, b = tree.query(boxes)  # box overlaps only; pieces of one line always touch, so drop those
    a = probes[a]
    keep = owner[a] != owner[b]
    a, b = a[keep], b[keep]
    hit = shapely.intersects(geoms[a], geoms[b]) if within <= 0 else shapely.dwithin(geoms[a], geoms[b], within)
    oa, ob = owner[a[hit]], owner[b[hit]]
    return {(int(min(x, y)), int(max(x, y))) for x, y in zip(oa.tolist(), ob.tolist(), strict=True)}


def _piece_ranges(lines: Sequence[Coords], size: int) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Pieces of at most ``size`` segments of the lines concatenated: first and last point, owner."""
    return piece_ranges(np.array([len(line) for line in lines], dtype=np.intp), size)


def piece_ranges(sizes: NDArray[np.integer], size: int) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Pieces of at most ``size`` segments of lines of ``sizes`` points, concatenated (lines of fewer than two
    points have none): first and last point (neighbouring pieces share one), and the line."""
    sizes = np.asarray(sizes, dtype=np.intp)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
    usable = np.flatnonzero(sizes >= 2)
    n, off = sizes[usable], offsets[usable]
    per_line = (n - 2) // size + 1
    owner = np.repeat(usable, per_line)
    k = np.arange(per_line.sum()) - np.repeat(np.cumsum(per_line) - per_line, per_line)
    first = np.repeat(off, per_line) + k * size
    last = np.minimum(first + size, np.repeat(off + n - 1, per_line))
    return first.astype(np.intp), last.astype(np.intp), owner.astype(np.intp)


@dataclass(frozen=True)
class SweepIndex:
    """Lines whose vertices each move on a straight path, cut into pieces, and the pairs of pieces of
    different lines whose paths' boxes overlap and that are no farther apart than they move: the only pairs
    that can ever meet. Only the pieces of those pairs are kept.

    Built once for a set of CCS (``base`` and ``top`` rows: a slice at any t lies between them, vertex by
    vertex), it answers for any two t per line (:meth:`contacts`) with no new spatial index.

    Attributes
    ----------
    base, top
        (N, 2) float64 points of the kept pieces, piece after piece, at t = 0 and t = 1 (metres).
    line_of_point
        (N,) index of the line each point belongs to.
    first, last, owner
        (P,) first and last point of each piece, and its line.
    p, q
        (K,) candidate pairs of pieces, each pair once, sorted by the lines of p, then of q.
    gap
        (K,) distance between the two pieces of each pair at t = 0 (metres).
    reach
        (P,) the largest distance a vertex of each piece moves from t = 0 to t = 1 (metres).
    """

    base: NDArray[np.float64]
    top: NDArray[np.float64]
    line_of_point: NDArray[np.intp]
    first: NDArray[np.intp]
    last: NDArray[np.intp]
    owner: NDArray[np.intp]
    p: NDArray[np.intp]
    q: NDArray[np.intp]
    gap: NDArray[np.float64]
    reach: NDArray[np.float64]

    @classmethod
    def of(cls, bases: Sequence[Coords], tops: Sequence[Coords], only: set[int] | None = None) -> SweepIndex:
        """Index lines given by their rows at t = 0 and t = 1; with ``only``, keep just the pairs of pieces
        that involve one of these line indices."""
        first, last, owner = _piece_ranges(bases, SWEEP_PIECE_SEGMENTS)
        sizes = np.array([len(line) for line in bases], dtype=np.intp)
        base = _stacked(bases)
        top = _stacked(tops)
        line_of_point = np.repeat(np.arange(len(bases)), sizes).astype(np.intp)
        if len(first) == 0:
            return cls.empty()
        # Every slice of a piece, at any t, stays inside the box of its rows at t = 0 and t = 1.
        lo = per_piece(np.minimum, np.minimum(base, top), first, last)
        hi = per_piece(np.maximum, np.maximum(base, top), first, last)
        boxes = np.hstack([lo, hi])
        probes = np.arange(len(boxes)) if only is None else np.flatnonzero(np.isin(owner, list(only)))
        p, q = box_pairs(boxes[probes], boxes)
        p = probes[p]
        # Each pair of pieces once: a probed piece meets a piece of a line that is not probed from its side only.
        keep = owner[p] < owner[q]
        if only is not None:
            keep |= (owner[p] != owner[q]) & ~np.isin(owner[q], list(only))
        p, q, gap, reach = _close_enough(base, top, first, last, p[keep], q[keep])
        if not len(p):
            return cls.empty()
        # Pairs of the same two lines side by side: once the lines meet, :meth:`contacts_in_steps` skips the rest.
        by_lines = np.lexsort((owner[q], owner[p]))
        p, q, gap = p[by_lines], q[by_lines], gap[by_lines]
        # Keep only the points of pieces in some pair: each step then moves and boxes just those.
        used, pair_index = np.unique(np.concatenate([p, q]), return_inverse=True)
        point, counts = _points_of(first[used], last[used])
        start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        return cls(
            base[point],
            top[point],
            line_of_point[point],
            start,
            start + counts - 1,
            owner[used],
            pair_index[: len(p)].astype(np.intp),
            pair_index[len(p) :].astype(np.intp),
            gap,
            reach[used],
        )

    @classmethod
    def empty(cls) -> SweepIndex:
        """An index with no pairs."""
        none, points = np.zeros(0, dtype=np.intp), np.zeros((0, 2))
        return cls(points, points, none, none, none, none, none, none, np.zeros(0), np.zeros(0))

    def contacts(
        self, t0: NDArray[np.float64], t1: NDArray[np.float64], shown: NDArray[np.bool_] | None = None
    ) -> set[tuple[int, int]]:
        """Pairs (i, j), i < j, of lines that meet while each line i goes from its slice at ``t0[i]`` to its
        slice at ``t1[i]``, all at one pace (``engine.ccsm.sweep``); lines not ``shown`` are left out."""
        tp0 = t0[self.line_of_point][:, None]
        tp1 = t1[self.line_of_point][:, None]
        a = self.base + tp0 * (self.top - self.base)
        b = self.base + tp1 * (self.top - self.base)
        # A slice at t is within t * reach of the base row; pieces farther apart at t = 0 than that, over
        # this motion, cannot meet in it (at small t, most pairs end here).
        t_most = np.maximum(np.abs(t0), np.abs(t1))[self.owner]
        keep = self.gap <= t_most[self.p] * self.reach[self.p] + t_most[self.q] * self.reach[self.q] + INPUT_TOUCH_M
        if shown is not None:
            keep &= shown[self.owner[self.p]] & shown[self.owner[self.q]]
        p, q = self.p[keep], self.q[keep]
        # Pieces whose boxes over this motion miss each other cannot meet either.
        lo = per_piece(np.minimum, np.minimum(a, b), self.first, self.last)
        hi = per_piece(np.maximum, np.maximum(a, b), self.first, self.last)
        near = np.all((lo[p] <= hi[q]) & (lo[q] <= hi[p]), axis=1)
        p, q = p[near], q[near]
        hit = pieces_meet(a, b, self.first, self.last, p, q)
        op, oq = self.owner[p[hit]], self.owner[q[hit]]
        return {(int(min(x, y)), int(max(x, y))) for x, y in zip(op.tolist(), oq.tolist(), strict=True)}

    def contacts_in_steps(
        self, t0: NDArray[np.float64], t1: NDArray[np.float64], shown: NDArray[np.bool_], threads: int = 1
    ) -> set[tuple[int, int]]:
        """Pairs (i, j), i < j, of lines that meet in some step s, each line i going from its slice at
        ``t0[i, s]`` to its slice at ``t1[i, s]`` if ``shown[i, s]``: the union of :meth:`contacts` over the
        columns, in one compiled pass that leaves a pair of pieces at its first contact and a pair of lines
        at its first pair of pieces that meets (per step, NumPy's overhead had cost more than the tests).

        ``threads`` share the pairs of pieces (the pass releases the GIL).
        """
        if not len(self.p):
            return set()
        cuts = np.linspace(0, len(self.p), max(1, threads) + 1).astype(np.intp)

        def part(k: int) -> NDArray[np.bool_]:
            lo, hi = cuts[k], cuts[k + 1]
            pairs = (self.p[lo:hi], self.q[lo:hi], self.gap[lo:hi], self.reach)
            args = (self.base, self.top, self.first, self.last, self.owner, pairs)
            return pairs_meet_in_steps(*args, t0, t1, shown, INPUT_TOUCH_M)

        if threads > 1:
            with ThreadPoolExecutor(max_workers=threads) as pool:
                hit = np.concatenate(list(pool.map(part, range(threads))))
        else:
            hit = part(0)
        op, oq = self.owner[self.p[hit]], self.owner[self.q[hit]]
        return {(int(min(x, y)), int(max(x, y))) for x, y in zip(op.tolist(), oq.tolist(), strict=True)}


def sweep_contacts(
    start: Sequence[Coords], end: Sequence[Coords], only: set[int] | None = None
) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of lines that meet at some moment while every vertex moves straight, at one
    pace, from its place in ``start`` to its place in ``end`` (``engine.ccsm.sweep``).

    Parameters
    ----------
    start, end
        The lines at both ends of the motion, (n_i, 2) arrays in one metric CRS; ``end[i]`` has the
        vertices of ``start[i]``.
    only
        If given, only pairs that involve one of these line indices are looked for.

    >>> a = np.array([[0.0, 0.0], [10.0, 0.0]])
    >>> b0, b1 = np.array([[5.0, 5.0], [5.0, 9.0]]), np.array([[5.0, -5.0], [5.0, -1.0]])
    >>> sweep_contacts([a, b0], [a, b1])  # b passes through a on its way down, and is apart at both ends
    {(0, 1)}
    """
    n = len(start)
    return SweepIndex.of(start, end, only).contacts(np.zeros(n), np.ones(n))


def concatenated_ranges(starts: NDArray[np.integer], counts: NDArray[np.integer]) -> NDArray[np.intp]:
    """starts[0] .. starts[0] + counts[0] - 1, then the same for every start, as one array.

    >>> concatenated_ranges(np.array([5, 0]), np.array([2, 3])).tolist()
    [5, 6, 0, 1, 2]
    """
    offsets = np.cumsum(counts) - counts
    return (np.repeat(starts, counts) + np.arange(counts.sum()) - np.repeat(offsets, counts)).astype(np.intp)


def _points_of(first: NDArray[np.intp], last: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the points first[i]..last[i] of every piece, in order, and each piece's point count."""
    counts = (last - first + 1).astype(np.intp)
    return concatenated_ranges(first, counts), counts


def _close_enough(
    base: NDArray[np.float64],
    top: NDArray[np.float64],
    first: NDArray[np.intp],
    last: NDArray[np.intp],
    p: NDArray[np.intp],
    q: NDArray[np.intp],
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """The pairs of pieces (p, q) that may ever meet: those no farther apart at t = 0 than their vertices move.
    Returns them with their distance at t = 0, and every piece's reach (its vertices' largest move).

    Every vertex of a slice lies within ``|top - base|`` of its base point, so every point of a slice's
    segment lies within the larger move of the segment's ends of the base segment's matching point: two
    pieces whose base rows are farther apart than the sum of their largest moves never meet, at any pair of
    t. On the sample this drops about 70% of the pairs whose boxes overlap, before any step is swept.
    """
    if not len(p):
        return p, q, np.zeros(0), np.zeros(len(first))
    move = np.linalg.norm(top - base, axis=1)
    reach = per_piece(np.maximum, move[:, None], first, last)[:, 0]
    # INPUT_TOUCH_M of slack: a pair exactly at the limit is kept, whatever the rounding of the distance.
    limit = reach[p] + reach[q] + INPUT_TOUCH_M
    # shapely.distance of the pieces' base rows, without geometries; measured only up to the limit (above it,
    # some number above it), since the pairs beyond are dropped whatever their distance
    gap = piece_gaps(base, first, last, p, q, limit)
    near = gap <= limit
    return p[near], q[near], gap[near], reach


def _stacked(lines: Sequence[Coords]) -> NDArray[np.float64]:
    """The lines' points concatenated, (N, 2) float64."""
    if not len(lines):
        return np.zeros((0, 2))
    return np.concatenate([np.asarray(line, dtype=np.float64) for line in lines])


def per_piece(
    ufunc: np.ufunc, values: NDArray[np.float64], first: NDArray[np.intp], last: NDArray[np.intp]
) -> NDArray[np.float64]:
    """``ufunc`` (np.minimum or np.maximum) of ``values`` over each piece's points first..last."""
    # reduceat runs up to the next piece's first point; a piece of the same line starts at this one's last.
    return np.asarray(ufunc(ufunc.reduceat(values, first, axis=0), values[last]))


class InputTouches:
    """Pairs (i, j), i < j, of lines that already meet (within ``INPUT_TOUCH_M``) in the input, asked pair by
    pair: only the few pairs whose slices meet are ever asked, so no index of every input line is built (that
    index cost a tenth of the repair on the sample). Works as the ``allowed`` container of
    :func:`find_new_crossings`. Each pair is decided by :func:`~engine.ccsm.near.lines_within` on the arrays:
    ``shapely.dwithin``'s decisions, without a geometry per line (GEOS, even prepared, cost 4x as much).
    """

    def __init__(self, lines: Sequence[Coords]) -> None:
        self.lines = lines
        self._known: dict[tuple[int, int], bool] = {}

    def __contains__(self, pair: object) -> bool:
        if not isinstance(pair, tuple) or len(pair) != 2:
            return False
        i, j = pair
        if (i, j) not in self._known:
            self._known[(i, j)] = bool(_touching([self.lines[i], self.lines[j]], [0], [1])[0])
        return self._known[(i, j)]

    def record(self, answers: dict[tuple[int, int], bool]) -> None:
        """Take answers made elsewhere (a block's worker, on the same base rows); a pair already answered keeps
        its first answer, as :meth:`learn` keeps it."""
        for pair, hit in answers.items():
            self._known.setdefault(pair, bool(hit))

    def learn(self, pairs: Iterable[tuple[int, int]]) -> None:
        """Ask these pairs now, together: each line of them is read once (all at once where ``lines`` has a
        ``take(indices)``, as the spool's base rows do), however many pairs it is in."""
        todo = sorted({pair for pair in pairs if pair not in self._known})
        read = getattr(self.lines, "take", None) or (lambda numbers: [self.lines[n] for n in numbers])
        for k in range(0, len(todo), LEARN_BATCH):
            self._known.update(pairs_touching(todo[k : k + LEARN_BATCH], read))


def pairs_touching(
    pairs: Sequence[tuple[int, int]], read: Callable[[list[int]], Sequence[Coords]]
) -> dict[tuple[int, int], bool]:
    """Whether the input lines of each pair are within ``INPUT_TOUCH_M`` of each other; ``read(numbers)`` gives
    the lines of ascending ``numbers``, each line read once however many pairs it is in."""
    if not pairs:
        return {}
    numbers = sorted({n for pair in pairs for n in pair})
    at = {n: k for k, n in enumerate(numbers)}
    hits = _touching(read(numbers), [at[i] for i, _ in pairs], [at[j] for _, j in pairs])
    return {pair: bool(hit) for pair, hit in zip(pairs, hits.tolist(), strict=True)}


def _touching(lines: Sequence[Coords], p: Sequence[int], q: Sequence[int]) -> NDArray[np.bool_]:
    """Whether lines ``p[k]`` and ``q[k]`` of ``lines`` are within ``INPUT_TOUCH_M`` of each other, for every k."""
    sizes = np.array([len(line) for line in lines], dtype=np.intp)
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
    p_arr, q_arr = np.asarray(p, dtype=np.intp), np.asarray(q, dtype=np.intp)
    return lines_within(_stacked(lines), first, first + sizes - 1, p_arr, q_arr, INPUT_TOUCH_M)


#: Pairs of lines :meth:`InputTouches.learn` reads and asks at a time (bounds the lines held at once).
LEARN_BATCH = 256


def new_contact_pairs(
    surfaces: Sequence[SurfaceRows],
    ladder: NDArray[np.float64],
    steps: Sequence[int],
    only: set[int] | None = None,
) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of surfaces whose visible slices meet at some scale from ``ladder[k]`` to
    ``ladder[k + 1]`` for k in ``steps``, whether or not they already meet in the input.

    Between two neighbouring ladder scales each slice's vertices move straight at one pace
    (docs/design.md section 4.8), so :class:`SweepIndex` covers every scale of the step, not a sample.
    The rings visible at ``ladder[k]`` are checked over the whole step (a ring only vanishes as the scale
    grows, so this is every ring shown in it).

    Parameters
    ----------
    surfaces
        CCS (or stretches of their rows), each with its ``t_at_scale`` table on ``ladder``.
    ladder, steps
        The scale ladder and the indices k of the steps (ladder[k], ladder[k + 1]) to check.
    only
        Restrict the search to contacts that involve these surfaces (the ones just rebuilt).
    """
    index = SweepIndex.of([s.base for s in surfaces], [s.top for s in surfaces], only)
    tables = np.array([s.t_at_scale for s in surfaces]).reshape(len(surfaces), -1)
    vanish = np.array([s.vanish_scale for s in surfaces])
    k = np.asarray(steps, dtype=np.intp)
    return index.contacts_in_steps(tables[:, k], tables[:, k + 1], vanish[:, None] > ladder[k][None, :], CHECK_THREADS)


def find_new_crossings(
    surfaces: Sequence[CCS],
    ladder: NDArray[np.float64],
    steps: Sequence[int],
    allowed: Container[tuple[int, int]],
    only: set[int] | None = None,
) -> set[int]:
    """Indices of surfaces whose slice meets another visible slice at any scale from ``ladder[k]`` to
    ``ladder[k + 1]`` for k in ``steps``, beyond ``allowed`` (pairs (i, j), i < j, that already meet in the
    input); the other parameters as for :func:`new_contact_pairs`."""
    return {i for pair in new_contact_pairs(surfaces, ladder, steps, only) if pair not in allowed for i in pair}


def _orientation(a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sign of the turn a -> b -> c for broadcast (..., 2) points: > 0 left, < 0 right, 0 on one line."""
    return np.sign(
        (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
    )


def lines_cross_properly(a: Coords, b: Coords) -> bool:
    """Whether a segment of ``a`` and a segment of ``b`` cross at a point inside both (a *proper* crossing).

    Touching (a vertex on the other line, shared vertices, overlapping collinear pieces) is not a proper
    crossing. This is the test for quantised tile geometry (docs/design.md section 4.8): on the integer tile
    grid, lines closer than one unit may be forced to touch, but never to cross properly, unless they cross.

    >>> lines_cross_properly(np.array([[0, 0], [4, 4]]), np.array([[0, 4], [4, 0]]))
    True
    >>> lines_cross_properly(np.array([[0, 0], [4, 0]]), np.array([[2, 0], [2, 3]]))  # a T: touching only
    False
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if len(a) < 2 or len(b) < 2:
        return False
    b1, b2 = b[None, :-1], b[None, 1:]
    bl, bh = np.minimum(b1, b2), np.maximum(b1, b2)
    for lo in range(0, len(a) - 1, 512):  # blocks of segments of a: bounded memory on long lines
        a1, a2 = a[lo : lo + 513][:-1, None], a[lo + 1 : lo + 513][:, None]
        near = np.all((np.minimum(a1, a2) <= bh) & (bl <= np.maximum(a1, a2)), axis=-1)
        if not near.any():
            continue
        i, j = np.nonzero(near)
        p1, p2, q1, q2 = a1[i, 0], a2[i, 0], b1[0, j], b2[0, j]
        proper = (_orientation(p1, p2, q1) * _orientation(p1, p2, q2) < 0) & (
            _orientation(q1, q2, p1) * _orientation(q1, q2, p2) < 0
        )
        if proper.any():
            return True
    return False


def proper_crossing_pairs(lines: Sequence[Coords]) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of lines that cross properly somewhere (:func:`lines_cross_properly`)."""
    return {(i, j) for i, j in crossing_pairs(lines) if lines_cross_properly(lines[i], lines[j])}
