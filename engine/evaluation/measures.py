"""The paper's quality measures (section 3.2) and the two this project adds.

- shape similarity per level and the largest jump between consecutive levels (Fig. 10, continuity);
- same-scale groups and MAAV (eq. 11, Table 2);
- linear density (eq. 12, Fig. 11);
- positional error (eq. 13, Table 3);
- crossings between different contours at one level (docs/design.md section 5: they must never cross).

Coordinates are (n, 2) float64 metres; a ring is passed without its repeated first vertex.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.errors import InvalidParameter
from engine.geom.polyline import closed_path
from engine.types import Coords

#: Largest similarity difference at which two results count as the same scale (paper section 3.2.3:
#: a Fréchet distance within 0.1 mm x 50,000 = 5 m gives Sim >= ~0.998).
SAME_SCALE_WINDOW = 0.002


def largest_jump(curve: NDArray[np.float64]) -> float:
    """Largest |Sim(i + 1) - Sim(i)| of a similarity curve ((levels,) floats); 0 for a single level.

    >>> largest_jump(np.array([1.0, 0.99, 0.9, 0.89]))
    0.09
    """
    values = np.asarray(curve, dtype=np.float64)
    if len(values) < 2:
        return 0.0
    return float(np.round(np.max(np.abs(np.diff(values))), 15))


def as_line(coords: Coords, closed: bool) -> shapely.LineString:
    """A shapely line of a contour (a ring closed by repeating its first vertex)."""
    xy = np.asarray(coords, dtype=np.float64)
    return shapely.linestrings(closed_path(xy) if closed and len(xy) > 2 else xy)


def positional_errors(initial: Coords, simplified: Coords, closed: bool) -> NDArray[np.float64]:
    """Positional error of every initial vertex (paper eq. 13), metres.

    The paper takes, for each vertex of the initial contour, the perpendicular distance to the corresponding
    segment of the simplified contour; here it is the distance to the simplified polyline (its nearest
    segment), which needs no correspondence and equals eq. 13 wherever the foot of the perpendicular falls
    on that segment.

    Parameters
    ----------
    initial
        (n, 2) the initial contour L0.
    simplified
        (k, 2) a simplified version of it (k >= 2).
    closed
        Whether both are rings.

    Returns
    -------
    (n,) float64

    Examples
    --------
    >>> positional_errors(np.array([[0, 0], [5, 3], [10, 0.0]]), np.array([[0, 0], [10, 0.0]]), False).tolist()
    [0.0, 3.0, 0.0]
    """
    line = as_line(simplified, closed)
    points = shapely.points(np.asarray(initial, dtype=np.float64))
    return np.asarray(shapely.distance(points, line), dtype=np.float64)


@dataclass(frozen=True)
class ErrorStats:
    """Mean, standard deviation (population) and maximum of positional errors, metres."""

    mean_m: float
    std_m: float
    max_m: float
    n: int

    @classmethod
    def of(cls, errors: NDArray[np.float64]) -> ErrorStats:
        """Statistics of a (n,) array of errors (NaN for an empty one)."""
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            return cls(float("nan"), float("nan"), float("nan"), 0)
        return cls(float(e.mean()), float(e.std()), float(e.max()), int(e.size))


def linear_density(simplified: Coords, closed: bool, width_m: float) -> float:
    """Length / area of the buffer of width ``width_m`` around a line (paper eq. 12), 1/m.

    The paper sets the buffer width to the standard deviation of the line's positional error. A width of 0
    (the line *is* the initial contour) has no buffer area: NaN.

    Examples
    --------
    A 10 m segment with a 1 m buffer (round caps, polygonal): about 10 / (2 * 10 + pi) = 0.43214

    >>> round(linear_density(np.array([[0, 0], [10, 0.0]]), False, 1.0), 4)
    0.4321
    """
    if not np.isfinite(width_m) or width_m < 0:
        raise InvalidParameter(f"buffer width must be a finite number >= 0, got {width_m}")
    if width_m == 0:
        return float("nan")
    line = as_line(simplified, closed)
    area = float(shapely.area(shapely.buffer(line, width_m, quad_segs=32)))
    return float(shapely.length(line)) / area


def pairwise_mean_abs(sims: NDArray[np.float64]) -> NDArray[np.float64]:
    """SdID of eq. 11 for every pair of methods: (g, m) similarities -> (m, m) mean |Sim_A - Sim_B|."""
    s = np.asarray(sims, dtype=np.float64)
    if s.ndim != 2 or s.shape[0] == 0:
        raise InvalidParameter(f"need a (groups, methods) array with at least one group, got shape {s.shape}")
    return np.mean(np.abs(s[:, :, None] - s[:, None, :]), axis=0)


def maav(sims: NDArray[np.float64]) -> float:
    """Max average absolute value (paper eq. 11) of one contour's same-scale groups.

    Parameters
    ----------
    sims
        (g, m) the similarity of each method's result (columns) in each group (rows); the paper has m = 3.

    Returns
    -------
    float
        The largest, over pairs of methods, of the mean over groups of their absolute similarity difference.

    Examples
    --------
    >>> maav(np.array([[0.950, 0.951, 0.949], [0.900, 0.900, 0.902]]))
    0.002
    """
    return float(np.round(np.max(pairwise_mean_abs(sims)), 15))


def same_scale_groups(
    curves: Sequence[NDArray[np.float64]],
    window: float = SAME_SCALE_WINDOW,
    max_similarity: float = 1.0 - SAME_SCALE_WINDOW,
) -> list[tuple[int, ...]]:
    """Groups of one level per method whose similarities lie within ``window`` of each other.

    Every level of every method whose similarity is below ``max_similarity`` is an anchor; each method
    contributes its level nearest the anchor's similarity, and the group is kept when its similarities span
    at most ``window``. Duplicate groups are dropped. Results at the same scale as the initial contour
    (Sim >= 1 - window) are not simplifications and make no group.

    Parameters
    ----------
    curves
        One (levels,) similarity curve per method.

    Returns
    -------
    list of tuples
        Each tuple holds one level index per method, in the order of ``curves``, sorted by mean similarity
        (highest first).

    Examples
    --------
    >>> a = np.array([1.0, 0.99, 0.95, 0.90])
    >>> b = np.array([1.0, 0.999, 0.951, 0.80])
    >>> same_scale_groups([a, b])
    [(2, 2)]
    """
    arrays = [np.asarray(c, dtype=np.float64) for c in curves]
    anchors = np.unique(np.concatenate([c[c < max_similarity] for c in arrays]))
    found: dict[tuple[int, ...], float] = {}
    for s in anchors:
        pick = tuple(int(np.argmin(np.abs(c - s))) for c in arrays)
        vals = np.array([c[i] for c, i in zip(arrays, pick, strict=True)])
        if vals.max() - vals.min() <= window + 1e-12 and vals.max() < max_similarity:
            found.setdefault(pick, float(vals.mean()))
    return sorted(found, key=lambda g: -found[g])


def crossing_pairs(lines: Sequence[Coords], closed: Sequence[bool]) -> tuple[int, int]:
    """Pairs of different contours that meet, and that properly cross.

    Parameters
    ----------
    lines
        One (k, 2) geometry per contour (rings without repeated vertex).
    closed
        Whether each is a ring.

    Returns
    -------
    (intersecting, crossing)
        Number of unordered pairs whose geometries intersect (any contact, touching included), and of those
        whose interiors cross (shapely ``crosses``).

    Examples
    --------
    >>> a = np.array([[0, 0], [2, 2.0]]); b = np.array([[0, 2], [2, 0.0]]); c = np.array([[5, 5], [6, 6.0]])
    >>> crossing_pairs([a, b, c], [False, False, False])
    (1, 1)
    """
    if len(lines) < 2:
        return (0, 0)
    geoms = np.array([as_line(xy, bool(cl)) for xy, cl in zip(lines, closed, strict=True)], dtype=object)
    tree = shapely.STRtree(geoms)
    left, right = tree.query(geoms, predicate="intersects")
    keep = left < right
    left, right = left[keep], right[keep]
    crossing = int(np.count_nonzero(shapely.crosses(geoms[left], geoms[right]))) if len(left) else 0
    return int(len(left)), crossing
