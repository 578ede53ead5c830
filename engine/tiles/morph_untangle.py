"""Morph tiles whose interpolated geometry never crosses: find the contours that would meet while a client
morphs them, and hold those still at one snap-rounded shape.

A client draws a morph tile's contour at fraction ``f`` of the level as ``start + w(f) (end - start)``, each
contour with its own ``w`` (docs/morph-tiles.md), piecewise linear in ``f`` between the eight steps. Inside one
step every vertex therefore moves on a straight line at a constant pace, and ``engine.ccsm.topology.SweepIndex``
finds, exactly, every pair of lines that comes to meet (touch or cross) at some moment of the step; lines that
cross already at the start are found directly (``engine.tiles.crossings``). Both ends are rounded to the grid
one vertex at a time, so lines closer than a grid unit can meet although their exact slices never do
(docs/design.md section 4.8).

Each contour of such a pair that still moves is *held*: both its layers get one snap-rounded shape
(``engine.tiles.snap_round``, rounded together with every contour of the tile; the renderer takes the shape at
the level's end, where every contour of the tile is shown), so it is drawn still through the level. Held
contours never cross one another (snap rounding); a moving contour that meets a held one is held in turn, and
the check repeats until no pair with a moving contour meets. It ends: once every contour is held the tile is
one snap-rounded drawing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.ccsm.topology import SweepIndex
from engine.tiles.crossings import crossing_owner_pairs
from engine.tiles.runs import ranges

#: Frames per level the ccsm-morph plugin draws (web/plugin): the moments a held contour must not cross at.
FRAMES_PER_LEVEL = 32
#: Rounds of holding contours before a tile holds them all: each round rebuilds the sweep index, and a long
#: chain of contours each meeting the next is cheaper to hold at once.
MAX_ROUNDS = 3


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


def morph_weights(t_samples: NDArray[np.float64]) -> NDArray[np.float64]:
    """(9, n) weights ``w`` of the end geometry at the nine steps of the level, from the (9, n) ``t`` samples
    exactly as a client computes them (docs/morph-tiles.md: 0 when t does not change)."""
    span = t_samples[-1] - t_samples[0]
    moving = span != 0
    w = np.zeros_like(t_samples)
    w[:, moving] = (t_samples[:, moving] - t_samples[0, moving]) / span[moving]
    return w


def _orientation(a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]) -> NDArray[np.float64]:
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _segment_pairs(
    parts: MorphParts, w: NDArray[np.float64], k: int, part_pairs: set[tuple[int, int]]
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Segments (first points p, q) of the part pairs that can meet in step k, and every point's place at the
    step's start and end (a point moves straight between them, at the pace of its contour's ``w``)."""
    owner_of_point = np.repeat(parts.part_owner, parts.part_len)
    part_of_point = np.repeat(np.arange(len(parts.part_len)), parts.part_len)
    start, end = parts.start.astype(np.float64), parts.end.astype(np.float64)
    at0 = start + w[k, owner_of_point][:, None] * (end - start)
    at1 = start + w[k + 1, owner_of_point][:, None] * (end - start)
    involved = np.zeros(len(parts.part_len), dtype=bool)
    involved[[i for pair in part_pairs for i in pair]] = True
    # Segment s runs from point s to s + 1; only the segments of parts in some pair.
    first = np.flatnonzero((part_of_point[:-1] == part_of_point[1:]) & involved[part_of_point[:-1]])
    ends = np.stack([at0[first], at0[first + 1], at1[first], at1[first + 1]])
    lo, hi = ends.min(axis=0), ends.max(axis=0)  # holds the segment at every moment of the step
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    p, q = shapely.STRtree(boxes).query(boxes)
    n_parts = len(parts.part_len)
    wanted = np.array([i * n_parts + j for i, j in part_pairs], dtype=np.int64)
    keys = part_of_point[first[p]].astype(np.int64) * n_parts + part_of_point[first[q]]
    keep = np.isin(keys, wanted)
    return first[p[keep]], first[q[keep]], at0, at1


def _cross_in_frames(
    parts: MorphParts, w: NDArray[np.float64], k: int, part_pairs: set[tuple[int, int]]
) -> set[tuple[int, int]]:
    """Contour pairs (a, b), a < b, among ``part_pairs`` (parts that meet somewhere in step k) that cross
    properly in a frame the plugin draws there (FRAMES_PER_LEVEL per level; lines that only touch on the grid
    need no holding). All pairs of a step are tested together, segment by segment, over every frame at once."""
    if not part_pairs:
        return set()
    p, q, at0, at1 = _segment_pairs(parts, w, k, part_pairs)
    per_step = FRAMES_PER_LEVEL // (w.shape[0] - 1)
    lam = np.arange(per_step + 1) / per_step
    # Every frame's place of the four points of each segment pair: (frames, pairs, 2).
    a1, a2, b1, b2 = (at0[i][None] + lam[:, None, None] * (at1[i] - at0[i])[None] for i in (p, p + 1, q, q + 1))
    proper = (_orientation(a1, a2, b1) * _orientation(a1, a2, b2) < 0) & (
        _orientation(b1, b2, a1) * _orientation(b1, b2, a2) < 0
    )
    owner_of_point = np.repeat(parts.part_owner, parts.part_len)
    hit = proper.any(axis=0)
    oa, ob = owner_of_point[p[hit]], owner_of_point[q[hit]]
    return {(int(min(a, b)), int(max(a, b))) for a, b in zip(oa.tolist(), ob.tolist(), strict=True)}


def meeting_owners(parts: MorphParts, w: NDArray[np.float64], held: NDArray[np.bool_]) -> set[int]:
    """Contours not yet held that meet another contour at some moment of the level (one of the two moving)."""
    if len(parts.part_len) < 2:
        return set()
    cut = np.cumsum(parts.part_len)[:-1]
    starts = np.split(parts.start.astype(np.float64), cut)
    ends = np.split(parts.end.astype(np.float64), cut)
    index = SweepIndex.of(starts, ends)
    owner = parts.part_owner
    # The sweep finds lines that come to meet; lines crossing already at the start are found directly.
    pairs = crossing_owner_pairs(parts.start, parts.part_len, owner)
    steps = w.shape[0] - 1
    for k in range(steps):
        to_check = set()
        for i, j in index.contacts(w[k][owner], w[k + 1][owner]):
            a, b = int(owner[i]), int(owner[j])
            # Held contours never cross one another (snap rounding): no frame to check.
            if a != b and not (held[a] and held[b]) and (min(a, b), max(a, b)) not in pairs:
                to_check.add((i, j))
        pairs |= _cross_in_frames(parts, w, k, to_check)
    found: set[int] = set()
    for a, b in pairs:
        if a != b and not (held[a] and held[b]):
            found.update(o for o in (a, b) if not held[o])
    return found


def untangle(parts: MorphParts, w: NDArray[np.float64], snap: Callable[[], MorphParts]) -> tuple[MorphParts, int]:
    """The morph tile's parts with every contour that would meet another while morphing held still.

    Parameters
    ----------
    parts
        The contours' parts at both ends of the level, rounded vertex by vertex.
    w
        (9, n) weight of the end geometry per contour at the level's nine steps (:func:`morph_weights`).
    snap
        Gives the same contours' exact shape at one moment of the level, snap-rounded all together (``start``
        equal to ``end``); called only when some contours meet.

    Returns
    -------
    (parts, held)
        The parts to encode and how many contours are held still.
    """
    held = np.zeros(w.shape[1], dtype=bool)
    current = parts
    snapped: MorphParts | None = None
    for _ in range(MAX_ROUNDS):
        meeting = meeting_owners(current, w, held)
        if not meeting:
            return current, int(held.sum())
        held[list(meeting)] = True
        snapped = snap() if snapped is None else snapped
        current = MorphParts.joined(parts.of_owners(~held), snapped.of_owners(held))
    # Still meeting after a few rounds: hold every contour, one snap-rounded drawing needs no more checks.
    snapped = snap() if snapped is None else snapped
    return snapped, w.shape[1]
