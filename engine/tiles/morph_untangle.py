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
from numpy.typing import NDArray

from engine.ccsm.topology import SweepIndex, lines_cross_properly
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


def _cross_in_frames(
    starts: list[NDArray[np.float64]],
    ends: list[NDArray[np.float64]],
    w: NDArray[np.float64],
    owner: NDArray[np.int64],
    i: int,
    j: int,
    k: int,
) -> bool:
    """Whether parts i and j, which meet somewhere in step k, cross properly in a frame the plugin draws there
    (FRAMES_PER_LEVEL per level; lines that only touch on the grid need no holding)."""
    per_step = FRAMES_PER_LEVEL // (w.shape[0] - 1)
    for m in range(per_step + 1):
        lam = m / per_step
        wi = w[k, owner[i]] + lam * (w[k + 1, owner[i]] - w[k, owner[i]])
        wj = w[k, owner[j]] + lam * (w[k + 1, owner[j]] - w[k, owner[j]])
        a = starts[i] + wi * (ends[i] - starts[i])
        b = starts[j] + wj * (ends[j] - starts[j])
        if lines_cross_properly(a, b):
            return True
    return False


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
        for i, j in index.contacts(w[k][owner], w[k + 1][owner]):
            a, b = int(owner[i]), int(owner[j])
            if a != b and (a, b) not in pairs and _cross_in_frames(starts, ends, w, owner, i, j, k):
                pairs.add((a, b))
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
