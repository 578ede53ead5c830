"""Visvalingam–Whyatt effective-area simplification (the default of mapshaper), for lines and rings.

The vertex whose triangle with its two current neighbours has the smallest area is removed first; its
neighbours' areas are then recomputed. Visvalingam and Whyatt's rule keeps the areas monotone: a recomputed
area smaller than the area of the vertex just removed is raised to it, so a vertex never goes "before" one
that was removed earlier and a threshold keeps exactly a prefix of the removal order. The removal runs once
in O(n log n) with an indexed binary heap; every level of a ladder and every threshold is then a filter.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.baselines._wm_kernels import init_links
from engine.baselines.common import count_schedule, min_vertices
from engine.tolerances import tolerance_for_scale
from engine.types import Coords


@njit(cache=True)
def _tri_area(xy: np.ndarray, a: int, b: int, c: int) -> float:  # pragma: no cover - compiled
    """Area in m² of the triangle of vertices ``a``, ``b``, ``c``."""
    twice = (xy[b, 0] - xy[a, 0]) * (xy[c, 1] - xy[a, 1]) - (xy[c, 0] - xy[a, 0]) * (xy[b, 1] - xy[a, 1])
    return 0.5 * abs(float(twice))


@njit(cache=True)
def _less(area: np.ndarray, i: int, j: int) -> bool:  # pragma: no cover - compiled
    """Heap order: smaller area first, then smaller vertex index, so ties resolve the same way every run."""
    return area[i] < area[j] or (area[i] == area[j] and i < j)


@njit(cache=True)
def _swap(heap: np.ndarray, pos: np.ndarray, a: int, b: int) -> None:  # pragma: no cover - compiled
    """Swap heap slots ``a`` and ``b``, keeping each vertex's slot in ``pos``."""
    heap[a], heap[b] = heap[b], heap[a]
    pos[heap[a]] = a
    pos[heap[b]] = b


@njit(cache=True)
def _sift_up(heap: np.ndarray, pos: np.ndarray, area: np.ndarray, k: int) -> None:  # pragma: no cover
    """Move heap slot ``k`` up until its parent is smaller."""
    while k > 0:
        parent = (k - 1) // 2
        if not _less(area, heap[k], heap[parent]):
            break
        _swap(heap, pos, k, parent)
        k = parent


@njit(cache=True)
def _sift_down(
    heap: np.ndarray, pos: np.ndarray, area: np.ndarray, k: int, size: int
) -> None:  # pragma: no cover
    """Move heap slot ``k`` down until both children are larger."""
    while True:
        left = 2 * k + 1
        if left >= size:
            break
        child = left
        if left + 1 < size and _less(area, heap[left + 1], heap[left]):
            child = left + 1
        if not _less(area, heap[child], heap[k]):
            break
        _swap(heap, pos, k, child)
        k = child


@njit(cache=True)
def vw_removal(xy: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Effective area and removal rank of every vertex under Visvalingam–Whyatt.

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres (a ring without its repeated first vertex).
    closed
        Whether ``xy`` is a ring. A line's end points are never removed; a ring stops at three vertices.

    Returns
    -------
    area : (n,) float64
        Effective area in m² at which each vertex is removed (monotone along the removal order); ``inf``
        for the vertices that are never removed.
    rank : (n,) int64
        Removal order: 0 for the first vertex removed; the never-removed vertices get the highest ranks
        (in index order), so keeping ``k`` vertices means keeping those with ``rank >= n - k``.
    """
    n = xy.shape[0]
    eff = np.full(n, np.inf)
    rank = np.full(n, -1, np.int64)
    key = np.full(n, np.inf)
    prv, nxt = init_links(n, closed)
    floor = 3 if closed else 2
    heap = np.empty(n, np.int64)
    pos = np.full(n, -1, np.int64)
    size = 0
    for i in range(n):
        if not closed and (i == 0 or i == n - 1):
            continue
        key[i] = _tri_area(xy, prv[i], i, nxt[i])
        heap[size] = i
        pos[i] = size
        size += 1
    for k in range(size // 2 - 1, -1, -1):
        _sift_down(heap, pos, key, k, size)
    alive = n
    last = 0.0
    r = 0
    while size > 0 and alive > floor:
        i = heap[0]
        size -= 1
        if size > 0:
            heap[0] = heap[size]
            pos[heap[0]] = 0
            _sift_down(heap, pos, key, 0, size)
        pos[i] = -1
        # Monotone rule: a vertex is never removed at a smaller area than one removed before it.
        last = max(last, key[i])
        eff[i] = last
        rank[i] = r
        r += 1
        alive -= 1
        p = prv[i]
        q = nxt[i]
        nxt[p] = q
        prv[q] = p
        for j in (p, q):
            k = pos[j]
            if k < 0:
                continue  # an end point of a line, never in the heap
            key[j] = max(_tri_area(xy, prv[j], j, nxt[j]), last)
            _sift_up(heap, pos, key, k)
            _sift_down(heap, pos, key, pos[j], size)
    for i in range(n):
        if rank[i] < 0:
            rank[i] = r
            r += 1
    return eff, rank


def effective_areas(xy: Coords, closed: bool) -> NDArray[np.float64]:
    """Visvalingam–Whyatt effective area of every vertex, in m² (``inf`` for the vertices always kept).

    Parameters
    ----------
    xy
        (n, 2) float64 vertices in metres, already checked (see :func:`engine.baselines.common.as_contour`).
    closed
        Whether ``xy`` is a ring.

    Returns
    -------
    (n,) float64

    Examples
    --------
    >>> import numpy as np
    >>> effective_areas(np.array([[0, 0], [1, 1], [2, 0], [3, 0.0]]), False).tolist()
    [inf, 1.5, 0.5, inf]
    """
    return vw_removal(np.ascontiguousarray(xy, dtype=np.float64), bool(closed))[0]


def vw_ladder(xy: Coords, closed: bool, levels: int) -> list[Coords]:
    """Visvalingam–Whyatt results with a kept-point count falling by a fixed share of ``n`` per level.

    Same schedule as :func:`engine.baselines.dp.dp_ladder`; level ``i`` keeps the vertices removed last.
    Levels are nested, a line keeps both ends, a ring at least three vertices.

    Returns
    -------
    list of (k, 2) float64
        ``levels`` arrays; level 0 is a copy of ``xy``.
    """
    n = len(xy)
    _, rank = vw_removal(xy, bool(closed))
    counts = count_schedule(n, min_vertices(closed), levels)
    return [xy[rank >= n - k] for k in counts]


def vw_at_scale(xy: Coords, closed: bool, scale: float) -> Coords:
    """Visvalingam–Whyatt at the area threshold of a map scale, ε² with ε = 0.1 mm × scale (m²).

    Keeps the vertices whose effective area is greater than ε² (as DP keeps significance > ε), plus the
    vertices that are always kept.

    Returns
    -------
    (k, 2) float64
        The kept vertices in their original order.
    """
    eps = tolerance_for_scale(scale)
    area, _ = vw_removal(xy, bool(closed))
    return xy[area > eps * eps]
