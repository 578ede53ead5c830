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
from numba import njit
from numpy.typing import NDArray

from engine.errors import InvalidContour, InvalidParameter
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
    if len(path) == 0:
        raise InvalidContour("a path needs at least one vertex")
    points, starts = _densified(np.ascontiguousarray(path, dtype=np.float64), float(spacing_m))
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
    path = np.ascontiguousarray(path, dtype=np.float64)
    initial, vertex_pos = densify_path(path, spacing_m)
    char_pos = vertex_pos[char]
    target = np.empty_like(initial)
    if not _partners(path, initial, char, char_pos, target):
        raise InvalidContour("a characteristic sub-polyline has zero length")
    return Correspondence(initial=initial, target=target, characteristic=char_pos)


# Both kernels do, sample by sample, the NumPy arithmetic they replaced (the same operations in the same order,
# so the samples are the same to the last bit): a contour of a few dozen vertices spent its correspondence in
# the overhead of a dozen NumPy calls, a tenth of its surface.
@njit(cache=True)
def _densified(path, spacing):  # pragma: no cover - compiled
    """The path's vertices with ``ceil(edge / spacing)`` equal pieces on every edge, and each vertex's index."""
    n = path.shape[0]
    pieces = np.empty(max(n - 1, 0), np.int64)
    total = 1
    for e in range(n - 1):
        pieces[e] = max(int(np.ceil(np.hypot(path[e + 1, 0] - path[e, 0], path[e + 1, 1] - path[e, 1]) / spacing)), 1)
        total += pieces[e]
    points = np.empty((total, 2))
    starts = np.empty(n, np.int64)
    at = 0
    for e in range(n - 1):
        starts[e] = at
        for step in range(pieces[e]):
            frac = step / pieces[e]
            for c in range(2):
                points[at, c] = path[e, c] + (path[e + 1, c] - path[e, c]) * frac
            at += 1
    starts[n - 1] = at
    points[at, 0] = path[n - 1, 0]
    points[at, 1] = path[n - 1, 1]
    return points, starts


@njit(cache=True)
def _partners(path, initial, char, char_pos, target):  # pragma: no cover - compiled
    """Fill ``target`` with each sample's partner on Ln, at its fraction of arc length along its piece of L0
    (the piece between the characteristic points at or before it and after it). False if a piece has no length."""
    m = initial.shape[0]
    arclen = np.empty(m)
    arclen[0] = 0.0
    for k in range(1, m):
        arclen[k] = arclen[k - 1] + np.hypot(initial[k, 0] - initial[k - 1, 0], initial[k, 1] - initial[k - 1, 1])
    last_piece = char.shape[0] - 2
    piece = 0
    for k in range(m):
        while piece < last_piece and char_pos[piece + 1] <= k:
            piece += 1
        s0 = arclen[char_pos[piece]]
        span = arclen[char_pos[piece + 1]] - s0
        if span <= 0.0:
            return False
        frac = (arclen[k] - s0) / span
        a = char[piece]
        b = char[piece + 1]
        for c in range(2):
            target[k, c] = path[a, c] + (path[b, c] - path[a, c]) * frac
    return True
