"""Wang–Müller bend simplification (Wang & Müller 1998, "Line generalization based on analysis of shape
characteristics", Cartography and GIS 25(1)), written here because no Python library implements it.

Bends and the compiled operators are in :mod:`engine.baselines._wm_kernels`. Each bend is measured by

- its shape, the compactness index ``cmp = 4 pi A / P**2`` of the polygon bend + baseline (``A`` its area,
  ``P`` its perimeter, baseline included): 1 for a circle, about 0.75 for a half circle, 0 for a flat bend;
- its adjusted size ``0.75 A / cmp``, compared with the reference bend, a half circle of diameter ``D``
  (area ``pi D**2 / 8``). The 0.75 makes a half circle's adjusted size almost its own area (1.0044 times).
  Note that ``0.75 A / cmp`` equals ``0.75 P**2 / (4 pi)``: the measure grows with the bend's perimeter and a
  long flat bend counts as large; the closed form is what is computed, so a flat bend (``A = 0``) needs no
  special case.

Two entry points:

- :func:`wm_at_scale` runs the operators until nothing changes: *exaggerate* an isolated small bend,
  *combine* a run of similar small bends, *eliminate* the remaining small bends, smallest first. No operator
  may create an intersection the line did not have.
- :func:`wm_ladder` is the paper's Table 1 ladder: each level removes 1 % of the original bend count
  (``1 / (levels - 1)`` in general), smallest adjusted size first, bends recomputed after each round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.baselines._wm_kernels import detect_bends, wm_generalize, wm_ladder_removal
from engine.geom.douglas_peucker import douglas_peucker_count
from engine.tolerances import MIN_VISIBLE_RING_SIDE_M
from engine.types import Coords


@dataclass(frozen=True)
class WMParams:
    """Thresholds of the Wang–Müller operators, each with the reason for its value.

    Attributes
    ----------
    gentle_inflection_deg
        A run of opposite turns totalling less than this is a gentle inflection, merged into its neighbours
        (Wang & Müller remove such wobbles before measuring bends). 5 degrees: below what a reader sees as a
        change of direction at map scale, and well below the turns of the DEM's grid staircase (45 degrees).
    isolation_ratio
        A small bend is isolated when both neighbouring bends are at most this curved (turning per metre)
        relative to it: it stands alone on a stretch of line that is otherwise nearly straight, and is then a
        landmark to keep (exaggerate) rather than noise among similar bends. 0.5: the neighbours turn at
        most half as fast.
    max_stretch
        Exaggeration stretches a bend away from its baseline by at most this factor. A bend that would need
        more is too small to be a feature at the target scale and is eliminated instead, so noise is never
        blown up. 2: up to about four times the adjusted size.
    similar_size_ratio
        Two neighbouring small bends are similar when the smaller adjusted size is at least this share of
        the larger. 0.5: within a factor two.
    similar_cmp_diff
        Two neighbouring small bends are similar only if their compactness indices also differ by at most
        this (cmp lies in [0, 1]; 0.2 tells a round bend from a flat one).
    max_iterations_per_vertex
        Safety bound on the operator loop (each pass removes a vertex or exaggerates a not-yet-moved bend,
        so the loop ends anyway; the bound only guards against a numerical cycle).
    diameter_on_paper_m
        Diameter of the reference half circle on the map, in metres of paper; ``D = diameter_on_paper_m x
        scale`` on the ground. 0.5 mm (:data:`engine.tolerances.MIN_VISIBLE_RING_SIDE_M`), the smallest closed
        shape a map can show: a bend is a closed shape with its baseline, and at 0.1 mm (DP's epsilon) WM's
        size measure keeps 99.9 % of a 90 m DEM's vertices even at 1:500,000 (see :func:`wm_at_scale`).
    """

    gentle_inflection_deg: float = 5.0
    isolation_ratio: float = 0.5
    max_stretch: float = 2.0
    similar_size_ratio: float = 0.5
    similar_cmp_diff: float = 0.2
    max_iterations_per_vertex: int = 4
    diameter_on_paper_m: float = MIN_VISIBLE_RING_SIDE_M


DEFAULT_WM_PARAMS = WMParams()


def reference_size(diameter_m: float) -> float:
    """Area in m² of the reference bend, a half circle of diameter ``diameter_m``.

    >>> round(reference_size(2.0), 6)
    1.570796
    """
    return math.pi * diameter_m * diameter_m / 8.0


def bend_count(xy: Coords, closed: bool, params: WMParams = DEFAULT_WM_PARAMS) -> int:
    """Number of bends of a line or ring, after gentle inflections are merged.

    >>> import numpy as np
    >>> bend_count(np.array([[0, 0], [1, 1], [2, 0], [3, 1], [4, 0.0]]), False)
    3
    """
    start, _, _ = detect_bends(
        np.ascontiguousarray(xy, dtype=np.float64), bool(closed), math.radians(params.gentle_inflection_deg)
    )
    return int(start.shape[0])


def _minimal(xy: Coords, closed: bool) -> Coords:
    """The minimal form: a line's two ends, or the Douglas–Peucker triangle of a ring."""
    if not closed:
        return xy[[0, -1]]
    return xy[douglas_peucker_count(xy, 3, closed=True)]


def wm_ladder(xy: Coords, closed: bool, levels: int, params: WMParams = DEFAULT_WM_PARAMS) -> list[Coords]:
    """Wang–Müller results whose bend count falls by a fixed share of the original count per level.

    Level ``i`` (``0 < i < levels - 1``) has at most ``round(B0 * (1 - i / (levels - 1)))`` bends, ``B0``
    the input's; with 100 levels that is the paper's 1 % bend reduction per iteration. The ladder only
    eliminates bends, so the levels are nested subsets of the input's vertices. The last level is the
    minimal form: a line's two end points, or for a ring the Douglas–Peucker triangle of the level before
    (a ring cannot lose all its bends by elimination: a convex ring has none and keeps its shape until then).

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres, already checked.
    closed
        Whether ``xy`` is a ring.
    levels
        Number of levels, >= 2.
    params
        Operator thresholds (only ``gentle_inflection_deg`` matters here).

    Returns
    -------
    list of (k, 2) float64
        ``levels`` arrays; level 0 is a copy of ``xy``.
    """
    gentle = math.radians(params.gentle_inflection_deg)
    b0 = bend_count(xy, closed, params)
    i = np.arange(1, levels - 1, dtype=np.float64)
    targets = np.floor(b0 * (1.0 - i / (levels - 1)) + 0.5).astype(np.int64)
    removed_at = wm_ladder_removal(xy, bool(closed), gentle, targets)
    out: list[Coords] = [xy[removed_at > lv] for lv in range(levels - 1)]
    out.append(_minimal(out[-1], closed))
    return out


def wm_at_scale(
    xy: Coords, closed: bool, scale: float, params: WMParams = DEFAULT_WM_PARAMS
) -> NDArray[np.float64]:
    """Wang–Müller at a map scale: reference half circle of diameter ``D = 0.5 mm x scale`` (metres).

    0.5 mm on paper is the smallest closed shape a map can show (the same rule that hides small rings).
    At DP's 0.1 mm WM barely acts: the reference half circle of diameter ``eps`` is only ``eps / 2`` high
    where DP drops any bump lower than ``eps``, and because the adjusted size is ``0.75 P**2 / (4 pi)`` even
    the smallest bend of a 90 m DEM contour (two ~50 m segments) compares with a half circle of about 60 m;
    on the Jacksboro sample WM at 0.1 mm keeps 99.9 % of the vertices at 1:500,000 (DP 20 %, VW 36 %).
    ``params.diameter_on_paper_m`` changes the rule.

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres, already checked.
    closed
        Whether ``xy`` is a ring (at least three vertices are kept).
    scale
        Map scale denominator, > 0.
    params
        Operator thresholds.

    Returns
    -------
    (k, 2) float64
        The generalized line (an exaggerated bend's vertices are moved; every other vertex is an input
        vertex).
    """
    ref = reference_size(params.diameter_on_paper_m * scale)
    return wm_generalize(
        xy,
        bool(closed),
        ref,
        math.radians(params.gentle_inflection_deg),
        params.isolation_ratio,
        params.max_stretch,
        params.similar_size_ratio,
        params.similar_cmp_diff,
        params.max_iterations_per_vertex * len(xy) + 10,
    )
