"""Reference discrete Fréchet distance for the tests of the compiled kernels and the similarity measure."""

from __future__ import annotations

import math

import numpy as np


def reference_frechet(p: np.ndarray, q: np.ndarray) -> float:
    """Eiter & Mannila's O(nm) dynamic programme, in plain Python (curves of at least one point each)."""
    n, m = len(p), len(q)
    if n == 0 or m == 0:
        raise ValueError("the discrete Fréchet distance needs a point on each curve")
    ca = [[0.0] * m for _ in range(n)]
    for i in range(n):
        for j in range(m):
            d = math.hypot(p[i][0] - q[j][0], p[i][1] - q[j][1])
            if i == 0 and j == 0:
                ca[i][j] = d
            elif i == 0:
                ca[i][j] = max(ca[i][j - 1], d)
            elif j == 0:
                ca[i][j] = max(ca[i - 1][j], d)
            else:
                ca[i][j] = max(min(ca[i - 1][j], ca[i - 1][j - 1], ca[i][j - 1]), d)
    return ca[-1][-1]
