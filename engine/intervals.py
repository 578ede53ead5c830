"""Contour intervals and index contours: one rule for every reader, renderer and writer.

The interval of a set is the largest step that every difference between its levels is a whole number of
(a robust greatest common divisor, :func:`infer_interval` says why); index contours are every
``INDEX_EVERY``-th interval.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Index contours are every 5th interval (the usual topographic convention).
INDEX_EVERY = 5
#: Elevations are compared after rounding to this many decimals (a micrometre: below any survey's precision).
ELEVATION_DECIMALS = 6
#: How far, as a fraction of the interval, a step between levels may lie from a whole number of intervals and
#: still count as one: noise in the levels (19.999 written for 20, feet converted to metres), not another grid.
#: Levels closer than this fraction of the median step are one level written twice.
INTERVAL_TOLERANCE = 0.01
#: The interval is sought down to the smallest step between levels divided by this: a finer common grid is a
#: coincidence of irregular levels (20 and 33 are both multiples of 1), not the interval they were drawn at.
MAX_DIVISOR = 10


def infer_interval(elevations: ArrayLike) -> float | None:
    """The contour interval of a set of elevations, or None with fewer than two distinct levels.

    The rule: the largest step ``d`` that divides every difference between the set's distinct levels, within
    :data:`INTERVAL_TOLERANCE` of ``d`` (a greatest common divisor that tolerates noise), sought among the
    smallest step divided by 1, 2, ... :data:`MAX_DIVISOR`, and then fitted to the levels (their span over the
    number of intervals in it, which averages the noise out). Levels closer together than
    :data:`INTERVAL_TOLERANCE` of the median step are first merged into one (19.999 and 20.0). When no such
    step exists, the levels lie on no grid and the most common step between consecutive levels is taken (the
    smaller one on a tie).

    Why the greatest common divisor: the interval is the grid every level lies on, and that is what its users
    need. The schedule ranks a level by the coarsest step it is a multiple of, index contours are the
    multiples of ``INDEX_EVERY`` intervals, and a schedule override's first step must divide the interval
    (:func:`engine.cartography.options.check_schedule_fits`); an interval that leaves some level off its grid
    (20 for levels 0, 20, 30) ranks that level as if it were a base contour that should not be there, so the
    most common step, which the build used before, is not enough. Missing levels (a gap of 40 in a 20 m set,
    index contours only where the slope is steep) leave the divisor unchanged; levels that are all a multiple
    of a coarser step than the one they were drawn at (only every other 20 m level present) give that coarser
    step, since nothing in the data shows the finer one. The price: supplementary contours (10 m lines in the
    flat parts of a 20 m map) make the interval 10, and index contours every 50 m; pass the interval
    explicitly for such a set (``read_source(..., interval=20)``).

    >>> infer_interval([100.0, 120.0, 140.0, 140.0, 200.0])
    20.0
    >>> infer_interval([0.0, 20.0, 30.0])
    10.0
    >>> infer_interval([0.0, 19.999, 40.001, 60.0])
    20.0
    >>> infer_interval([0.0, 20.0, 33.0])  # no grid within a tenth of the smallest step: the most common step
    13.0
    """
    distinct: NDArray[np.float64] = np.unique(np.round(np.asarray(elevations, dtype=np.float64), ELEVATION_DECIMALS))
    distinct = distinct[np.isfinite(distinct)]
    if len(distinct) < 2:
        return None
    levels = _merge_close_levels(distinct)
    if len(levels) < 2:
        return None
    steps = np.diff(levels)
    smallest = float(steps.min())
    span = float(levels[-1] - levels[0])
    for divisor in range(1, MAX_DIVISOR + 1):
        whole = np.round(steps / (smallest / divisor))  # intervals in each step
        # Fitted to every level rather than the smallest step alone, whose noise would grow with each multiple.
        fitted = span / float(whole.sum())
        if np.all(np.abs(steps - whole * fitted) <= INTERVAL_TOLERANCE * fitted):
            return round(fitted, ELEVATION_DECIMALS)
    values, counts = np.unique(np.round(steps, ELEVATION_DECIMALS), return_counts=True)
    return float(values[np.argmax(counts)])  # np.unique sorts: the first of the most common is the smallest


def _merge_close_levels(levels: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sorted distinct levels with the runs closer than INTERVAL_TOLERANCE of the median step each made one
    (their mean).

    >>> np.round(_merge_close_levels(np.array([0.0, 19.999, 20.0, 40.0])), 6).tolist()
    [0.0, 19.9995, 40.0]
    """
    steps = np.diff(levels)
    starts = np.concatenate([[True], steps >= INTERVAL_TOLERANCE * float(np.median(steps))])
    if starts.all():
        return levels
    group = np.cumsum(starts) - 1
    merged: NDArray[np.float64] = np.bincount(group, weights=levels) / np.bincount(group)
    return merged


def is_index(elevation: float, interval: float | None) -> bool:
    """True when ``elevation`` is a multiple of ``INDEX_EVERY`` intervals.

    >>> is_index(1000.0, 20.0), is_index(1020.0, 20.0), is_index(1000.0, None)
    (True, False, False)
    """
    if not interval:
        return False
    q = elevation / (INDEX_EVERY * interval)
    return abs(q - round(q)) < 1e-6


#: Spellings of the vertical units (metres, feet and fathoms of 1.8288 m, the charts' unit of depth), in user
#: options and in rasters' metadata, by the unit they name.
UNIT_NAMES = {
    "m": "m",
    "metre": "m",
    "meter": "m",
    "metres": "m",
    "meters": "m",
    "ft": "ft",
    "foot": "ft",
    "feet": "ft",
    "us survey foot": "ft",
    "foot_us": "ft",
    "us-ft": "ft",
    "ftus": "ft",
    "fm": "fm",
    "fathom": "fm",
    "fathoms": "fm",
}
