"""Row significance of CCS rows for tiles: which rows a tile of a given grid size can leave out.

The Douglas–Peucker significance of row ``i`` of the 4-D polyline ``(base_x, base_y, top_x, top_y)`` bounds
how far both rows stray from the chord between the rows kept around it, with one chord parameter for both.
A slice at any t is ``(1 - t) base + t top``, so its row strays from the sliced chord by at most the same
amount: dropping every row whose significance is below half a tile-grid unit moves no slice by more than
that, at every t. A tile then processes a few rows per grid cell instead of every stored row.

The kernel is geometry's (:func:`engine.geom.kernels.dp_significance`); this module says what it means here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from engine.geom.kernels import dp_significance


def row_significance(xy: NDArray[np.float64], zw: NDArray[np.float64] | None = None) -> NDArray[np.float32]:
    """Significance (metres, float32, ends ``inf``) of each row of an (M, 2) array, or of two taken together.

    >>> line = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    >>> row_significance(line).tolist()
    [inf, 0.5, inf]
    """
    first = np.ascontiguousarray(xy, dtype=np.float64)
    second = None if zw is None else np.ascontiguousarray(zw, dtype=np.float64)
    return dp_significance(first, second).astype(np.float32)
