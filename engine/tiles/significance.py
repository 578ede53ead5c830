"""Row significance of CCS rows for tiles: which rows a tile of a given grid size can leave out.

The Douglas–Peucker significance of row ``i`` of the 4-D polyline ``(base_x, base_y, top_x, top_y)`` bounds
how far both rows stray from the chord between the rows kept around it, with one chord parameter for both.
A slice at any t is ``(1 - t) base + t top``, so its row strays from the sliced chord by at most the same
amount: dropping every row whose significance is below half a tile-grid unit moves no slice by more than
that, at every t. A tile then processes a few rows per grid cell instead of every stored row.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True)
def _significance(p: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    n, k = p.shape
    sig = np.zeros(n)
    if n == 0:
        return sig
    sig[0] = np.inf
    sig[n - 1] = np.inf
    s_first = np.empty(n, np.int64)
    s_last = np.empty(n, np.int64)
    s_cap = np.empty(n)
    s_first[0] = 0
    s_last[0] = n - 1
    s_cap[0] = np.inf
    top = 1
    while top > 0:
        top -= 1
        first = s_first[top]
        last = s_last[top]
        cap = s_cap[top]
        if last - first < 2:
            continue
        seg2 = 0.0
        for j in range(k):
            d = p[last, j] - p[first, j]
            seg2 += d * d
        best = -1.0
        best_i = first + 1
        for i in range(first + 1, last):
            u = 0.0
            if seg2 > 0.0:
                for j in range(k):
                    u += (p[i, j] - p[first, j]) * (p[last, j] - p[first, j])
                u /= seg2
                if u < 0.0:
                    u = 0.0
                elif u > 1.0:
                    u = 1.0
            d2 = 0.0
            for j in range(k):
                q = p[i, j] - p[first, j] - u * (p[last, j] - p[first, j])
                d2 += q * q
            if d2 > best:
                best = d2
                best_i = i
        s = min(np.sqrt(best), cap)
        sig[best_i] = s
        s_first[top] = first
        s_last[top] = best_i
        s_cap[top] = s
        top += 1
        s_first[top] = best_i
        s_last[top] = last
        s_cap[top] = s
        top += 1
    return sig


def row_significance(*rows: NDArray[np.float64]) -> NDArray[np.float32]:
    """Significance (metres, float32, ends ``inf``) of each row of one or more (M, 2) arrays taken together.

    >>> line = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    >>> row_significance(line).tolist()
    [inf, 0.5, inf]
    """
    p = np.ascontiguousarray(np.concatenate(rows, axis=1), dtype=np.float64)
    return _significance(p).astype(np.float32)
