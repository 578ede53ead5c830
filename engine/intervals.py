"""Contour intervals and index contours: one rule for every reader, renderer and writer.

The interval of a set is the most common step between its consecutive distinct elevations; when two steps
are equally common, the smaller one wins (levels 0, 20, 30 give 10: a finer grid that holds every level,
rather than 20, which would leave 30 off the grid). Index contours are every ``INDEX_EVERY``-th interval.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: Index contours are every 5th interval (the usual topographic convention).
INDEX_EVERY = 5
#: Elevations are compared after rounding to this many decimals (a micrometre: below any survey's precision).
ELEVATION_DECIMALS = 6


def infer_interval(elevations: ArrayLike) -> float | None:
    """The contour interval of a set of elevations, or None with fewer than two distinct levels.

    >>> infer_interval([100.0, 120.0, 140.0, 140.0, 200.0])
    20.0
    >>> infer_interval([0.0, 20.0, 30.0])
    10.0
    """
    levels = np.unique(np.round(np.asarray(elevations, dtype=np.float64), ELEVATION_DECIMALS))
    if len(levels) < 2:
        return None
    steps, counts = np.unique(np.round(np.diff(levels), ELEVATION_DECIMALS), return_counts=True)
    return float(steps[np.argmax(counts)])  # np.unique sorts: the first of the most common is the smallest


def is_index(elevation: float, interval: float | None) -> bool:
    """True when ``elevation`` is a multiple of ``INDEX_EVERY`` intervals.

    >>> is_index(1000.0, 20.0), is_index(1020.0, 20.0), is_index(1000.0, None)
    (True, False, False)
    """
    if not interval:
        return False
    q = elevation / (INDEX_EVERY * interval)
    return abs(q - round(q)) < 1e-6


#: Spellings of the two vertical units, in user options and in rasters' metadata, by the unit they name.
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
}
