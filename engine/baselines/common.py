"""Input checks and the level schedule shared by the baseline simplifiers.

Every baseline takes a contour as ``(n, 2)`` float64 coordinates in metres plus a ``closed`` flag; a ring is
given *without* repeating its first vertex (the convention of :class:`engine.types.Contour`).
"""

from __future__ import annotations

import numbers

import numpy as np
from numpy.typing import NDArray

from engine import checks
from engine.errors import InvalidContour, InvalidParameter
from engine.method_names import BASELINE_METHODS
from engine.types import Coords


def min_vertices(closed: bool) -> int:
    """Fewest vertices a simplified contour keeps: both ends of a line, a triangle for a ring."""
    return 3 if closed else 2


def check_method(method: object) -> str:
    """Return ``method`` if it names a baseline, else raise :class:`InvalidParameter` naming it."""
    return checks.check_method(method, BASELINE_METHODS)


def check_levels(levels: object) -> int:
    """Return ``levels`` as an int if it is an integer >= 2 (level 0 is the input, the last the minimum)."""
    if isinstance(levels, bool) or not isinstance(levels, numbers.Integral) or int(levels) < 2:
        raise InvalidParameter(f"levels must be an integer >= 2, got {levels!r}")
    return int(levels)


def as_contour(coords: Coords, closed: bool) -> Coords:
    """Check and normalise one contour's coordinates.

    Parameters
    ----------
    coords
        (n, 2) vertices in metres. A ring may also be given closed (last vertex = first): the repeated vertex
        is dropped, so every result follows the library's convention.
    closed
        Whether ``coords`` is a ring.

    Returns
    -------
    (n, 2) float64, C-contiguous
        A new array (the caller's array is never modified or returned).

    Raises
    ------
    InvalidParameter
        Not an (n, 2) array.
    InvalidContour
        Non-finite coordinates, or fewer than 2 vertices (line) / 3 vertices (ring).
    """
    xy = np.array(coords, dtype=np.float64, order="C", copy=True)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise InvalidParameter(f"coords must have shape (n, 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise InvalidContour("coords contain NaN or infinite values")
    if closed and len(xy) > 3 and np.array_equal(xy[0], xy[-1]):
        xy = xy[:-1].copy()
    need = min_vertices(closed)
    if len(xy) < need:
        kind = "ring" if closed else "line"
        raise InvalidContour(f"a {kind} needs at least {need} vertices, got {len(xy)}")
    return xy


def count_schedule(n: int, floor: int, levels: int) -> NDArray[np.intp]:
    """Vertices kept at each level when every level drops the same share of the original count.

    The paper's Table 1 ("reduction rate of points 1 %", 100 iterations): level ``i`` keeps
    ``round(n - (n - floor) * i / (levels - 1))`` vertices, so level 0 keeps all ``n`` and the last level
    keeps ``floor``. Halves round up so the schedule does not depend on banker's rounding.

    >>> count_schedule(10, 2, 5).tolist()
    [10, 8, 6, 4, 2]
    """
    i = np.arange(levels, dtype=np.float64)
    counts = np.floor(n - (n - floor) * i / (levels - 1) + 0.5).astype(np.intp)
    return np.maximum(counts, min(floor, n))
