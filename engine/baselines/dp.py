"""Douglas–Peucker as the paper's baseline: a 100-level ladder by kept-point count, and a result at a scale.

Both reuse :mod:`engine.geom.douglas_peucker` (the same DP that makes CCSM's target contour), so the baseline and CCSM
agree on what DP keeps; nothing here reimplements DP.
"""

from __future__ import annotations

import numpy as np

from engine.baselines.common import count_schedule, min_vertices
from engine.geom.douglas_peucker import douglas_peucker, significance
from engine.tolerances import tolerance_for_scale
from engine.types import Coords


def dp_ladder(xy: Coords, closed: bool, levels: int) -> list[Coords]:
    """Douglas–Peucker results with a kept-point count falling by a fixed share of ``n`` per level.

    Level ``i`` keeps the ``count_schedule(n, floor, levels)[i]`` most significant vertices, with the same
    ordering and tie-break as :func:`engine.geom.douglas_peucker.douglas_peucker_count` (significance descending, then
    vertex index), so every level equals ``douglas_peucker_count(xy, count, closed)`` and the levels are
    nested. The significance is computed once for all levels.

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres, already checked (ring without its repeated first vertex).
    closed
        Whether ``xy`` is a ring (the last level is then DP's minimal triangle).
    levels
        Number of levels, >= 2.

    Returns
    -------
    list of (k, 2) float64
        ``levels`` arrays; level 0 is a copy of ``xy``.
    """
    n = len(xy)
    sig = significance(xy, closed)
    order = np.lexsort((np.arange(n), -sig))
    counts = count_schedule(n, min_vertices(closed), levels)
    return [xy[np.sort(order[:k])] for k in counts]


def dp_at_scale(xy: Coords, closed: bool, scale: float) -> Coords:
    """Douglas–Peucker at the tolerance of a map scale, ε = 0.1 mm × scale (in metres).

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres, already checked.
    closed
        Whether ``xy`` is a ring (then at least a triangle is kept).
    scale
        Map scale denominator, > 0.

    Returns
    -------
    (k, 2) float64
        The kept vertices in their original order.
    """
    return xy[douglas_peucker(xy, tolerance_for_scale(scale), closed)]
