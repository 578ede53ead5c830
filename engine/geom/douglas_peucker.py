"""Douglas–Peucker, returning the indices it keeps, for open lines and closed rings.

The characteristic points of CCSM (the target contour ``Ln``) are Douglas–Peucker's kept vertices of ``L0``.
Rings follow docs/design.md section 4: DP of a ring never collapses to one point; the ring is split at two far
apart vertices, both halves are simplified, and at least a triangle remains.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from engine.errors import InvalidParameter
from engine.geom.kernels import dp_significance, ring_anchor_pair, ring_significance
from engine.types import Coords

IndexArray = NDArray[np.intp]


def _as_coords(coords: Coords) -> Coords:
    xy = np.ascontiguousarray(coords, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise InvalidParameter(f"coordinates must have shape (n, 2), got {xy.shape}")
    return xy


def ring_anchors(coords: Coords) -> tuple[int, int]:
    """Two far apart vertices of a ring, where it is split for Douglas–Peucker.

    The vertex farthest from the first vertex, then the vertex farthest from that one: two passes that find
    the ring's diameter or come close to it, in O(n).

    Returns
    -------
    (a, b)
        Vertex indices with ``a < b``.
    """
    a, b = ring_anchor_pair(_as_coords(coords))
    return int(a), int(b)


def significance(coords: Coords, closed: bool = False) -> NDArray[np.float64]:
    """Douglas–Peucker significance of each vertex, in metres.

    DP at tolerance ``eps`` keeps exactly the vertices whose significance is greater than ``eps``; the
    vertices every result keeps (ends of an open line; for a ring its two anchors and the vertex farthest from
    their chord, which make the minimal triangle) have ``inf``.

    Parameters
    ----------
    coords
        (n, 2) vertices in metres; a ring without its repeated first vertex.
    closed
        Whether ``coords`` is a ring.

    Returns
    -------
    (n,) float64
    """
    xy = _as_coords(coords)
    n = len(xy)
    if not closed or n < 4:
        sig = dp_significance(xy)
        if closed:
            sig[:] = np.inf  # a ring of three vertices is already the minimal triangle
        return sig
    # One compiled pass for a ring: its anchors, both halves and the triangle were a dozen NumPy calls, most of
    # a small ring's target.
    return ring_significance(xy)


def douglas_peucker(coords: Coords, epsilon_m: float, closed: bool = False) -> IndexArray:
    """Indices of the vertices Douglas–Peucker keeps at a tolerance.

    Parameters
    ----------
    coords
        (n, 2) vertices in metres (a ring without its repeated first vertex).
    epsilon_m
        Tolerance in metres, >= 0.
    closed
        Whether ``coords`` is a ring (then at least three vertices are kept).

    Returns
    -------
    (k,) intp
        Kept vertex indices in ascending order; an open line keeps its first and last vertex.

    Examples
    --------
    >>> import numpy as np
    >>> douglas_peucker(np.array([[0, 0], [1, 0.1], [2, 0], [3, 5], [4, 0.0]]), 0.5).tolist()
    [0, 2, 3, 4]
    """
    if not np.isfinite(epsilon_m) or epsilon_m < 0:
        raise InvalidParameter(f"epsilon_m must be a finite number >= 0, got {epsilon_m}")
    sig = significance(coords, closed)
    return np.flatnonzero(sig > epsilon_m)


def douglas_peucker_count(coords: Coords, n_keep: int, closed: bool = False) -> IndexArray:
    """Indices of the ``n_keep`` most significant vertices (DP run until that many are left).

    Ties are broken by vertex order so the result is deterministic. ``n_keep`` is raised to the minimum
    (2 for a line, 3 for a ring) and lowered to the vertex count.
    """
    xy = _as_coords(coords)
    floor = 3 if closed else 2
    n_keep = int(min(max(n_keep, floor), len(xy)))
    sig = significance(xy, closed)
    order = np.lexsort((np.arange(len(sig)), -sig))
    return np.sort(order[:n_keep])
