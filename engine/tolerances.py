"""Numeric tolerances, each with the reason for its value (kept in one place, as trimesh does)."""

from __future__ import annotations

from dataclasses import dataclass

#: Smallest difference the eye can tell apart on a printed map (cartographic convention), in metres of paper.
MIN_VISIBLE_DISTANCE_M = 0.0001  # 0.1 mm

#: Smallest side of a closed shape a map can still show, in metres of paper (docs/design.md section 4).
MIN_VISIBLE_RING_SIDE_M = 0.0005  # 0.5 mm


@dataclass(frozen=True)
class Tolerances:
    """Distances below which two things are treated as one.

    Attributes
    ----------
    duplicate_m
        Consecutive vertices closer than this are one vertex: a DEM with whole-metre heights makes contours
        with repeated vertices and zero-length pieces (docs/design.md section 6); 1 mm is far below any map scale.
    zero_length_m
        A contour shorter than this has no shape to simplify.
    """

    duplicate_m: float = 1e-3
    zero_length_m: float = 1e-2


DEFAULT_TOLERANCES = Tolerances()


def tolerance_for_scale(scale: float) -> float:
    """Ground distance in metres of the smallest visible distance at a scale denominator.

    >>> tolerance_for_scale(50_000)
    5.0
    """
    return MIN_VISIBLE_DISTANCE_M * scale


def min_ring_area_for_scale(scale: float) -> float:
    """Ground area in m² below which a closed ring cannot be shown at a scale denominator (0.5 mm square).

    >>> round(min_ring_area_for_scale(100_000))
    2500
    """
    side = MIN_VISIBLE_RING_SIDE_M * scale
    return side * side
