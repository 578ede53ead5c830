"""Topology by scale: how many pairs of contours that are apart in the input touch or cross at a map scale, per
method (issue 13; docs/design.md section 4.8).

CCSM is built as served (target at the target scale, crossing repair on) and sliced at each contour's t for the
scale; Douglas–Peucker, Wang–Müller and Visvalingam–Whyatt run at each scale the way per-zoom tile tools do.
Pairs that already meet in the input (lines of one level touching at a saddle, as GDAL's contours do) are left
out, and so are the rings too small for a scale, for every method alike.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.baselines import simplify_at_scale
from engine.ccsm.build import BuiltSet, build_contour_set
from engine.ccsm.regression import t_for_scale
from engine.ccsm.topology import INPUT_TOUCH_M, crossing_pairs
from engine.errors import InvalidParameter
from engine.geom.polyline import closed_path
from engine.method_names import BASELINE_METHODS, CCSM, COMPARED_METHODS
from engine.params import BuildParams
from engine.types import Contour, ContourSet, Coords

#: Methods of the table, in column order.
SCALE_METHODS: tuple[str, ...] = COMPARED_METHODS


@dataclass(frozen=True)
class ScaleTopology:
    """Pairs of contours apart in the input that touch or cross, per method and scale."""

    #: (S,) scale denominators.
    scales: NDArray[np.float64]
    #: Method names, the row order of ``new_pairs``.
    methods: tuple[str, ...]
    #: (M, S) int64 pairs apart in the input that touch or cross at each scale.
    new_pairs: NDArray[np.int64]
    #: Pairs that already meet in the input (left out of every count).
    input_pairs: int
    #: Contours checked.
    contours: int

    def rows(self) -> list[tuple[float, ...]]:
        """(scale, count per method) per scale, for a table."""
        return [(float(s), *(int(v) for v in self.new_pairs[:, k])) for k, s in enumerate(self.scales)]


def _as_path(coords: Coords, closed: bool) -> Coords:
    return closed_path(coords) if closed else coords


def _surface_line(built: BuiltSet, inputs: Sequence[Contour], i: int, method: str, scale: float) -> Coords:
    """Contour ``i`` sliced on its continuous changing surface at its t for the scale."""
    surface = built.surfaces[i]
    return surface.at(t_for_scale(built.model.ladder, surface.t_at_scale, scale))


def _baseline_line(built: BuiltSet, inputs: Sequence[Contour], i: int, method: str, scale: float) -> Coords:
    """Contour ``i`` as the per-scale simplifier ``method`` gives it at the scale (a ring as a closed path)."""
    c = inputs[i]
    return _as_path(simplify_at_scale(method, c.coords, c.closed, scale), c.closed)


#: How each method of the table draws a contour at a scale.
_LINE_AT: dict[str, Callable[[BuiltSet, Sequence[Contour], int, str, float], Coords]] = {
    CCSM: _surface_line,
    **dict.fromkeys(BASELINE_METHODS, _baseline_line),
}


def _line_at(built: BuiltSet, inputs: Sequence[Contour], i: int, method: str, scale: float) -> Coords:
    """Contour ``i`` by ``method`` at a scale (a ring as a closed path)."""
    return _LINE_AT[method](built, inputs, i, method, scale)


def topology_scales(source_scale: float, target_scale: float, n: int) -> NDArray[np.float64]:
    """``n`` scale denominators log-spaced from the source scale to twice the target scale (1:50,000 to
    1:1,000,000 by default), past the target where every CCSM contour is at its target shape.

    >>> topology_scales(50_000, 500_000, 3).round().tolist()
    [50000.0, 223607.0, 1000000.0]
    """
    if n < 1:
        raise InvalidParameter(f"the number of topology scales must be >= 1, got {n}")
    return np.geomspace(source_scale, 2 * target_scale, n)


def topology_by_scale(
    contour_set: ContourSet,
    scales: Sequence[float] | NDArray[np.float64],
    *,
    source_scale: float = 50_000.0,
    target_scale: float = 500_000.0,
    workers: int | None = None,
) -> ScaleTopology:
    """Count, at each scale and for each method, the pairs of contours apart in the input that touch or cross.

    Parameters
    ----------
    contour_set
        Contours in a metric CRS.
    scales
        Scale denominators.
    source_scale, target_scale
        The CCSM build's scales (the served set-up).
    workers
        Build processes; None = one per core.
    """
    scales = np.asarray(scales, dtype=np.float64)
    built = build_contour_set(
        contour_set, BuildParams(source_scale=source_scale, target_scale=target_scale), workers=workers
    )
    by_id = {c.id: c for c in contour_set.contours}
    ids = [s.contour_id for s in built.surfaces]
    inputs = [by_id[i] for i in ids]
    allowed = crossing_pairs([_as_path(c.coords, c.closed) for c in inputs], within=INPUT_TOUCH_M)
    counts = np.zeros((len(SCALE_METHODS), len(scales)), dtype=np.int64)
    for k, scale in enumerate(scales.tolist()):
        shown = [i for i, s in enumerate(built.surfaces) if s.vanish_scale > scale]
        for m, method in enumerate(SCALE_METHODS):
            lines = [_line_at(built, inputs, i, method, scale) for i in shown]
            met = {(shown[a], shown[b]) for a, b in crossing_pairs(lines)}
            counts[m, k] = len(met - allowed)
    return ScaleTopology(scales, SCALE_METHODS, counts, len(allowed), len(ids))
