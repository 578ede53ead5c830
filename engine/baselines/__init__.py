"""The baseline simplifiers CCSM is compared with, run as in Qian et al. (2021), section 3.2 and Table 1.

- ``"dp"``: Douglas–Peucker (:mod:`engine.baselines.dp`, on top of :mod:`engine.geom.douglas_peucker`);
- ``"wm"``: Wang–Müller bend simplification (:mod:`engine.baselines.wang_muller`);
- ``"vw"``: Visvalingam–Whyatt effective areas, mapshaper's default (:mod:`engine.baselines.vw`).

Two calls cover every use: :func:`ladder` gives the paper's 100 progressively simplified results (1 % of the
points, or of the bends, fewer per level), :func:`simplify_at_scale` gives a method's own result at a map
scale. Coordinates are (n, 2) float64 metres in a projected CRS; a ring is passed and returned without
repeating its first vertex.

Examples
--------
>>> import numpy as np
>>> line = np.array([[0, 0], [10, 3], [20, -2], [30, 4], [40, 0.0]])
>>> [len(level) for level in ladder("dp", line, closed=False, levels=4)]
[5, 4, 3, 2]
>>> simplify_at_scale("dp", line, closed=False, scale=50_000).shape
(2, 2)
"""

from __future__ import annotations

from collections.abc import Callable

from engine.baselines.common import as_contour, check_levels, check_method
from engine.baselines.dp import dp_at_scale, dp_ladder
from engine.baselines.vw import effective_areas, vw_at_scale, vw_ladder
from engine.baselines.wang_muller import DEFAULT_WM_PARAMS, WMParams, bend_count, wm_at_scale, wm_ladder
from engine.checks import check_scale
from engine.method_names import BASELINE_METHODS
from engine.types import Coords

__all__ = [
    "BASELINE_METHODS",
    "DEFAULT_WM_PARAMS",
    "WMParams",
    "bend_count",
    "effective_areas",
    "ladder",
    "simplify_at_scale",
]

_LADDERS: dict[str, Callable[[Coords, bool, int], list[Coords]]] = {
    "dp": dp_ladder,
    "wm": wm_ladder,
    "vw": vw_ladder,
}

_AT_SCALE: dict[str, Callable[[Coords, bool, float], Coords]] = {
    "dp": dp_at_scale,
    "wm": wm_at_scale,
    "vw": vw_at_scale,
}

assert tuple(_LADDERS) == tuple(_AT_SCALE) == BASELINE_METHODS, "every baseline name has both implementations"


def ladder(method: str, coords: Coords, closed: bool, levels: int = 100) -> list[Coords]:
    """Progressively simplified versions of one contour, as the paper's Table 1 made them.

    Parameters
    ----------
    method
        ``"dp"``, ``"wm"`` or ``"vw"``.
    coords
        (n, 2) vertices in metres (a ring without its repeated first vertex; a repeated one is dropped).
    closed
        Whether ``coords`` is a ring.
    levels
        Number of results, >= 2 (the paper: 100).

    Returns
    -------
    list of (k, 2) float64
        ``levels`` arrays. Level 0 is the input unchanged, the last level the most simplified form (a line's
        two end points; a ring's minimal triangle). DP and VW keep
        ``round(n - (n - floor) * i / (levels - 1))`` vertices at level ``i`` (floor 2 for a line, 3 for a
        ring); WM allows ``round(B0 * (1 - i / (levels - 1)))`` bends. Vertex counts never rise, and every
        method's levels are nested subsets of the input's vertices.

    Raises
    ------
    InvalidParameter
        Unknown ``method``, ``levels`` not an integer >= 2, or ``coords`` not of shape (n, 2).
    InvalidContour
        Non-finite coordinates or too few vertices.

    Examples
    --------
    >>> import numpy as np
    >>> ring = np.array([[0, 0], [4, 0], [4, 3], [2, 1], [0, 3.0]])
    >>> [len(level) for level in ladder("vw", ring, closed=True, levels=3)]
    [5, 4, 3]
    """
    method = check_method(method)
    levels = check_levels(levels)
    xy = as_contour(coords, bool(closed))
    return _LADDERS[method](xy, bool(closed), levels)


def simplify_at_scale(method: str, coords: Coords, closed: bool, scale: float) -> Coords:
    """A method's own result at a map scale denominator.

    DP uses epsilon = 0.1 mm x ``scale`` (:func:`engine.tolerances.tolerance_for_scale`), VW the area
    threshold epsilon², WM a reference half circle of diameter D = epsilon (see
    :func:`engine.baselines.wang_muller.wm_at_scale` for why).

    Parameters
    ----------
    method
        ``"dp"``, ``"wm"`` or ``"vw"``.
    coords
        (n, 2) vertices in metres (a ring without its repeated first vertex).
    closed
        Whether ``coords`` is a ring (at least a triangle is kept; a line keeps both ends).
    scale
        Map scale denominator (50_000 for 1:50,000), > 0.

    Returns
    -------
    (k, 2) float64

    Raises
    ------
    InvalidParameter
        Unknown ``method``, ``scale`` <= 0 or not finite, or ``coords`` not of shape (n, 2).
    InvalidContour
        Non-finite coordinates or too few vertices.
    """
    method = check_method(method)
    value = check_scale(scale)
    xy = as_contour(coords, bool(closed))
    return _AT_SCALE[method](xy, bool(closed), value)
