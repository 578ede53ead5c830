"""Small polyline measures shared by the engine (lengths, areas, arc-length resampling)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from engine.errors import InvalidParameter
from engine.geom.kernels import path_length_of, resampled
from engine.types import Coords


def closed_path(coords: Coords) -> Coords:
    """The ring's vertices with its first vertex repeated at the end: (n + 1, 2)."""
    return np.concatenate([coords, coords[:1]])


def segment_lengths(coords: Coords) -> NDArray[np.float64]:
    """Lengths of the (n - 1) segments of a polyline, in the unit of ``coords``."""
    return np.hypot(*np.diff(coords, axis=0).T)


def cumulative_length(coords: Coords) -> NDArray[np.float64]:
    """Arc length at each vertex, starting at 0: (n,)."""
    return np.concatenate([[0.0], np.cumsum(segment_lengths(coords))])


def path_length(coords: Coords, closed: bool = False) -> float:
    """Length of a polyline, or of a ring including its closing segment: ``segment_lengths`` summed as NumPy
    sums them, in one compiled pass (a build measures every contour a few times)."""
    return float(path_length_of(np.ascontiguousarray(coords, dtype=np.float64).reshape(-1, 2), bool(closed)))


def ring_area(coords: Coords) -> float:
    """Unsigned area of a ring (shoelace), in squared units of ``coords``.

    >>> ring_area(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]))
    2.0
    """
    return float(ring_areas(np.asarray(coords)[None])[0])


def ring_areas(rings: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unsigned areas of k rings of n vertices each, (k, n, 2) -> (k,) (shoelace), in squared units.

    >>> ring_areas(np.array([[[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]], [[0.0, 0.0], [1.0, 0.0], [0.0, 3.0]]]))
    array([1. , 1.5])
    """
    # Relative to the first vertex: at UTM magnitudes the raw products cancel and lose the small ring's area.
    # That vertex is then (0, 0), so the closing term x[n-1] y[0] - y[n-1] x[0] vanishes.
    local = rings - rings[:, :1]
    x, y = local[..., 0], local[..., 1]
    return np.abs(np.einsum("kn,kn->k", x[:, :-1], y[:, 1:]) - np.einsum("kn,kn->k", y[:, :-1], x[:, 1:])) / 2.0


def points_at_lengths(coords: Coords, cumlen: NDArray[np.float64], at: NDArray[np.float64]) -> Coords:
    """Points of a polyline at given arc lengths (clamped to the line), by linear interpolation."""
    return np.column_stack([np.interp(at, cumlen, coords[:, 0]), np.interp(at, cumlen, coords[:, 1])])


def resample_by_arclength(coords: Coords, n_points: int) -> Coords:
    """``n_points`` points equally spaced along a polyline, both ends included.

    Parameters
    ----------
    coords
        (n, 2) polyline, n >= 2, with positive length.
    n_points
        Number of output points, >= 2.

    Returns
    -------
    (n_points, 2) float64

    Examples
    --------
    >>> resample_by_arclength(np.array([[0.0, 0.0], [4.0, 0.0]]), 3).tolist()
    [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]
    """
    if n_points < 2:
        raise InvalidParameter(f"n_points must be >= 2, got {n_points}")
    if len(coords) == 0:
        raise InvalidParameter("cannot resample a polyline with no vertices")
    # Compiled: the same numbers as points_at_lengths(coords, cumulative_length(coords), np.linspace(0, length,
    # n_points)), without the dozen NumPy calls a short contour's similarity reference spent most of its time in.
    return resampled(np.ascontiguousarray(coords, dtype=np.float64), int(n_points))
