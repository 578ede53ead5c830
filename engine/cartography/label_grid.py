"""The label placement's walk over its candidates, compiled (numba): the one part of a build's labels that runs
in the build process, serially (engine.cartography.labels._keep_apart says what it decides and why)."""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.typed import Dict

_CELL = types.UniTuple(types.int64, 2)


@njit(cache=True, nogil=True)
def kept_apart(xy, box, mpp, order, biggest):  # pragma: no cover - compiled
    """The labels ``order`` keeps, in the order kept: each unless its box (``box`` pixels wide and high at ``mpp``
    metres per pixel, its first zoom's) meets a kept one's at the later first zoom of the two; kept labels filed
    in a grid of cells at least ``biggest`` x ``mpp`` of the label at hand wide, refiled at half the width
    whenever that halves (engine.cartography.labels._keep_apart)."""
    kept = np.empty(len(order), dtype=np.int64)
    n_kept = 0
    after = np.full(len(xy), -1, dtype=np.int64)  # the label filed before it in its cell (a list per cell)
    grid = Dict.empty(key_type=_CELL, value_type=types.int64)  # a cell: the last label filed there
    cell = np.inf
    for j in order:
        reach = biggest * mpp[j]
        if reach < cell / 2 or not np.isfinite(cell):
            cell = max(reach, 1e-9)
            grid = Dict.empty(key_type=_CELL, value_type=types.int64)
            for q in range(n_kept):
                i = kept[q]
                key = (np.int64(np.floor(xy[i, 0] / cell)), np.int64(np.floor(xy[i, 1] / cell)))
                after[i] = grid[key] if key in grid else -1
                grid[key] = i
        cx, cy = np.int64(np.floor(xy[j, 0] / cell)), np.int64(np.floor(xy[j, 1] / cell))
        meets = False
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                near = (cx + dx, cy + dy)
                i = grid[near] if near in grid else -1
                while i >= 0 and not meets:
                    m = min(mpp[j], mpp[i])
                    half_x = (box[j, 0] + box[i, 0]) / 2 * m
                    half_y = (box[j, 1] + box[i, 1]) / 2 * m
                    meets = abs(xy[i, 0] - xy[j, 0]) < half_x and abs(xy[i, 1] - xy[j, 1]) < half_y
                    i = after[i]
        if not meets:
            kept[n_kept] = j
            n_kept += 1
            key = (cx, cy)
            after[j] = grid[key] if key in grid else -1
            grid[key] = j
    return kept[:n_kept]
