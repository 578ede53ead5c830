"""How long a contour the build takes: each contour's vertex count against a limit.

A contour's build (its surface fit, crossings and repair) takes time and memory that grow faster than its vertex
count, and one contour is built by one worker: a line of a million vertices held a worker for minutes. The
service refuses such a contour at upload (``CCSM_MAX_CONTOUR_VERTICES``, docs/service.md); the command line
builds what it is given.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from engine.types import Contour, FeatureId


@dataclass(frozen=True)
class OversizedContour:
    """A contour with more vertices than the limit: its id (``"{fid}:{part}"`` for a MultiLineString's part)
    and its vertex count."""

    id: FeatureId
    vertices: int


def oversized_contours(contours: Iterable[Contour], max_vertices: int | None) -> list[OversizedContour]:
    """The contours with more than ``max_vertices`` vertices, in input order (none when the limit is None).

    Vertices are counted as the build takes them: after consecutive duplicates merge, a closed ring without its
    repeated first vertex (:attr:`engine.types.Contour.n_vertices`). Each part of a MultiLineString is a contour of
    its own, built on its own, so the limit holds per part.

    Examples
    --------
    >>> import numpy as np
    >>> line = Contour("a", 100.0, np.zeros((5, 2)), closed=False)
    >>> oversized_contours([line], 4), oversized_contours([line], 5), oversized_contours([line], None)
    ([OversizedContour(id='a', vertices=5)], [], [])
    """
    if max_vertices is None:
        return []
    return [OversizedContour(c.id, c.n_vertices) for c in contours if c.n_vertices > max_vertices]
