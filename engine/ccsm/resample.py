"""Correspondence resampling of the initial contour L0 and the target contour Ln (paper section 2.1 (2)).

Between two consecutive characteristic points, the piece of ``L0`` and the straight segment of ``Ln``
correspond. Both are sampled with the same number of points, proportional to the piece's arc length, so a
point on one side always has its partner on the corresponding piece of the other side.

Rule where the paper is silent (docs/design.md section 3): the samples on ``L0`` keep every vertex of ``L0`` and
add equally spaced points on any edge longer than ``spacing_m``; each sample's partner on ``Ln`` sits at the
same fraction of arc length along the corresponding segment. Keeping ``L0``'s own vertices is what lets the
fitted surface pass through ``L0``'s corners instead of cutting them by metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.errors import InvalidContour, InvalidParameter
from engine.geom.polyline import segment_lengths
from engine.types import Coords


@dataclass(frozen=True)
class Correspondence:
    """Corresponding samples of ``L0`` and ``Ln``.

    Attributes
    ----------
    initial
        (N, 2) samples on L0, in metres. Every vertex of L0 is one of them.
    target
        (N, 2) partner samples on Ln, in metres.
    characteristic
        (k,) indices into the samples of the characteristic points (where ``initial == target``).
    """

    initial: Coords
    target: Coords
    characteristic: NDArray[np.intp]


def densify_path(path: Coords, spacing_m: float) -> tuple[Coords, NDArray[np.intp]]:
    """Insert equally spaced points on every edge longer than ``spacing_m``.

    Returns
    -------
    points
        (N, 2) the path's vertices plus the inserted points, in order.
    vertex_index
        (n,) position of each original vertex in ``points``.
    """
    edges = segment_lengths(path)
    pieces = np.maximum(np.ceil(edges / spacing_m).astype(np.intp), 1)
    starts = np.concatenate([[0], np.cumsum(pieces)])
    total = int(starts[-1]) + 1
    edge_of = np.repeat(np.arange(len(edges)), pieces)
    step = np.arange(total - 1) - starts[edge_of]
    frac = step / pieces[edge_of]
    a = path[edge_of]
    b = path[edge_of + 1]
    points = np.empty((total, 2))
    points[:-1] = a + (b - a) * frac[:, None]
    points[-1] = path[-1]
    return points, starts.astype(np.intp)


def correspond(path: Coords, characteristic: NDArray[np.intp], spacing_m: float) -> Correspondence:
    """Sample ``L0`` (``path``) and its target ``Ln`` (the polyline through ``path[characteristic]``).

    Parameters
    ----------
    path
        (n, 2) initial contour in metres; for a ring, the closed path with its first vertex repeated at the end.
    characteristic
        Ascending indices into ``path`` of the characteristic points; must include 0 and n - 1.
    spacing_m
        Largest gap between consecutive samples on ``L0``, metres (> 0).

    Returns
    -------
    Correspondence
    """
    if not spacing_m > 0 or not np.isfinite(spacing_m):
        raise InvalidParameter(f"spacing_m must be a positive number, got {spacing_m}")
    char = np.asarray(characteristic, dtype=np.intp)
    if len(char) < 2 or char[0] != 0 or char[-1] != len(path) - 1 or np.any(np.diff(char) <= 0):
        raise InvalidContour("characteristic points must be ascending and include both ends")
    initial, vertex_pos = densify_path(path, spacing_m)
    # Arc length of every sample, and of every characteristic point, along L0.
    arclen = np.concatenate([[0.0], np.cumsum(segment_lengths(initial))])
    char_pos = vertex_pos[char]
    piece = np.searchsorted(char_pos, np.arange(len(initial)), side="right") - 1
    piece = np.minimum(piece, len(char) - 2)
    s0 = arclen[char_pos[piece]]
    s1 = arclen[char_pos[piece + 1]]
    span = s1 - s0
    if np.any(span <= 0):
        raise InvalidContour("a characteristic sub-polyline has zero length")
    frac = (arclen - s0) / span
    a = path[char[piece]]
    b = path[char[piece + 1]]
    target = a + (b - a) * frac[:, None]
    return Correspondence(initial=initial, target=target, characteristic=char_pos)
