"""Crossings between different contours (docs/design.md section 5: contours must never cross at any t).

Lines are cut into short pieces before they go into the spatial index: a 200 km contour has a bounding box
that overlaps everything, its pieces do not, so the index rejects almost every candidate pair cheaply.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.types import Coords

if TYPE_CHECKING:
    from engine.ccsm.ccs import CCS

#: Threads for the crossing checks: GEOS releases the GIL, so the scales are checked side by side.
CHECK_THREADS = 2

#: Segments per indexed piece: small boxes for the index, few enough pieces to keep the query cheap.
PIECE_SEGMENTS = 24


def _pieces(lines: Sequence[Coords]) -> tuple[NDArray[np.object_], NDArray[np.intp]]:
    """Cut every line into pieces of at most PIECE_SEGMENTS segments (neighbouring pieces share a vertex)."""
    sizes = np.array([len(line) for line in lines], dtype=np.intp)
    usable = np.flatnonzero(sizes >= 2)
    if len(usable) == 0:
        return np.empty(0, dtype=object), np.empty(0, dtype=np.intp)
    coords = np.concatenate([lines[int(i)] for i in usable])
    n = sizes[usable]
    offsets = np.concatenate([[0], np.cumsum(n)[:-1]])
    per_line = (n - 2) // PIECE_SEGMENTS + 1
    owner = np.repeat(usable, per_line)
    k = np.arange(per_line.sum()) - np.repeat(np.cumsum(per_line) - per_line, per_line)
    first = np.repeat(offsets, per_line) + k * PIECE_SEGMENTS
    last = np.minimum(first + PIECE_SEGMENTS, np.repeat(offsets + n - 1, per_line))
    counts = last - first + 1
    piece_of_point = np.repeat(np.arange(len(first)), counts)
    point = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(first, counts)
    geoms = shapely.linestrings(coords[point], indices=piece_of_point)
    return geoms, owner.astype(np.intp)


def crossing_pairs(lines: Sequence[Coords], only: set[int] | None = None) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of different lines that intersect (cross or touch).

    Parameters
    ----------
    lines
        Polylines as (n, 2) arrays (a ring as a closed path), all in one CRS.
    only
        If given, only pairs that involve one of these line indices are looked for.
    """
    geoms, owner = _pieces(lines)
    if len(geoms) == 0:
        return set()
    tree = shapely.STRtree(geoms)
    probes = np.arange(len(geoms)) if only is None else np.flatnonzero(np.isin(owner, list(only)))
    a, b = tree.query(geoms[probes])  # box overlaps only; pieces of one line always touch, so drop those
    a = probes[a]
    keep = owner[a] != owner[b]
    a, b = a[keep], b[keep]
    hit = shapely.intersects(geoms[a], geoms[b])
    oa, ob = owner[a[hit]], owner[b[hit]]
    return {(int(min(x, y)), int(max(x, y))) for x, y in zip(oa.tolist(), ob.tolist(), strict=True)}


def neighbours(surfaces: Sequence[CCS], of: set[int]) -> NDArray[np.intp]:
    """Indices of the surfaces whose extent (over every t) overlaps that of one of ``of``, those included."""
    boxes = shapely.box(*np.array([s.bounds for s in surfaces]).T)
    tree = shapely.STRtree(boxes)
    _, hits = tree.query(boxes[sorted(of)])
    return np.unique(np.concatenate([hits, np.array(sorted(of), dtype=np.intp)]))


def find_new_crossings(
    surfaces: Sequence[CCS],
    ladder: NDArray[np.float64],
    steps: Sequence[int],
    allowed: set[tuple[int, int]],
    only: set[int] | None = None,
) -> set[int]:
    """Indices of surfaces whose slice crosses another visible slice at a checked scale, beyond ``allowed``.

    Parameters
    ----------
    surfaces
        Every CCS of the set, each with its ``t_at_scale`` table on ``ladder``.
    ladder, steps
        The scale ladder and the indices of it to check.
    allowed
        Pairs (i, j), i < j, that already meet in the input.
    only
        Restrict the search to crossings that involve these surfaces (the ones just rebuilt) and their
        neighbours.
    """
    candidates = np.arange(len(surfaces)) if only is None else neighbours(surfaces, only)
    vanish = np.array([surfaces[i].vanish_scale for i in candidates])

    def check(k: int) -> set[int]:
        visible = candidates[vanish > ladder[k]]
        local_only = None if only is None else {int(j) for j in np.flatnonzero(np.isin(visible, list(only)))}
        if local_only is not None and not local_only:
            return set()
        lines = [surfaces[i].at(float(surfaces[i].t_at_scale[k])) for i in visible]
        found: set[int] = set()
        for a, b in crossing_pairs(lines, local_only):
            pair = (int(visible[a]), int(visible[b]))
            if pair not in allowed:
                found.update(pair)
        return found

    with ThreadPoolExecutor(max_workers=CHECK_THREADS) as pool:
        return set().union(*pool.map(check, steps))
