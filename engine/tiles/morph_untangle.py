"""Morph tiles whose interpolated geometry never crosses: find the contours that would cross while a client
morphs them, and hold those still at one snap-rounded shape.

A client draws a morph tile's contour at fraction ``f`` of the level as ``start + w(f) (end - start)``, each
contour with its own ``w`` (docs/morph-tiles.md), piecewise linear in ``f`` between the eight steps. Inside one
step every vertex therefore moves on a straight line at a constant pace, and ``engine.tiles.morph_crossings``
finds, exactly, every pair of contours that crosses properly at some moment of the step, at any fraction a
client may draw. Both ends are rounded to the grid one vertex at a time, so lines closer than a grid unit can
cross although their exact slices never do; lines the grid only forces to touch are left moving
(docs/design.md section 4.8).

Each contour of such a pair that still moves is *held*: both its layers get one snap-rounded shape
(``engine.tiles.snap_round``, rounded together with every contour of the tile; the renderer takes the shape at
the level's end, where every contour of the tile is shown), so it is drawn still through the level. Held
contours never cross one another (snap rounding); a moving contour that crosses a held one is held in turn, and
the check repeats until no pair with a moving contour crosses. It ends: once every contour is held the tile is
one snap-rounded drawing.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from engine.tiles.morph_crossings import MorphParts, morph_crossing_pairs

#: Rounds of holding contours before a tile holds them all: each round checks the tile again, and a long
#: chain of contours each crossing the next is cheaper to hold at once.
MAX_ROUNDS = 3


def morph_weights(t_samples: NDArray[np.float64]) -> NDArray[np.float64]:
    """(9, n) weights ``w`` of the end geometry at the nine steps of the level, from the (9, n) ``t`` samples
    exactly as a client computes them (docs/morph-tiles.md: 0 when t does not change)."""
    span = t_samples[-1] - t_samples[0]
    moving = span != 0
    w = np.zeros_like(t_samples)
    w[:, moving] = (t_samples[:, moving] - t_samples[0, moving]) / span[moving]
    return w


def crossing_owners(parts: MorphParts, w: NDArray[np.float64], held: NDArray[np.bool_]) -> set[int]:
    """Contours not yet held that cross another contour properly at some fraction of the level (one of the two
    moving; ``engine.tiles.morph_crossings``)."""
    pairs = morph_crossing_pairs(parts, w, skip=held)
    return {o for pair in pairs for o in pair if not held[o]}


def untangle(parts: MorphParts, w: NDArray[np.float64], snap: Callable[[], MorphParts]) -> tuple[MorphParts, int]:
    """The morph tile's parts with every contour that would cross another while morphing held still.

    Parameters
    ----------
    parts
        The contours' parts at both ends of the level, rounded vertex by vertex.
    w
        (9, n) weight of the end geometry per contour at the level's nine steps (:func:`morph_weights`).
    snap
        Gives the same contours' exact shape at one moment of the level, snap-rounded all together (``start``
        equal to ``end``); called only when some contours cross.

    Returns
    -------
    (parts, held)
        The parts to encode and how many contours are held still.
    """
    held = np.zeros(w.shape[1], dtype=bool)
    current = parts
    snapped: MorphParts | None = None
    for _ in range(MAX_ROUNDS):
        crossing = crossing_owners(current, w, held)
        if not crossing:
            return current, int(held.sum())
        held[list(crossing)] = True
        snapped = snap() if snapped is None else snapped
        current = MorphParts.joined(parts.of_owners(~held), snapped.of_owners(held))
    # Still crossing after a few rounds: hold every contour, one snap-rounded drawing needs no more checks.
    snapped = snap() if snapped is None else snapped
    return snapped, w.shape[1]
