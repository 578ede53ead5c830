"""Compiled inner loops (numba): the few places where a Python loop over vertices would dominate the build.

Each kernel has a plain-Python twin in the tests that checks it on small inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def dp_significance(xy: np.ndarray, zw: np.ndarray | None = None) -> np.ndarray:  # pragma: no cover - compiled
    """Douglas–Peucker significance of every vertex of an open polyline: (n, 2) ``xy``, or the 4-D polyline
    ``(xy, zw)`` when ``zw`` (n, 2) is given.

    ``sig[i]`` is the largest tolerance at which Douglas–Peucker keeps vertex ``i``: the distance of ``i`` to
    the chord of the segment it splits, capped by the significance of every ancestor split (DP only looks
    inside a segment that was itself split). The two end points get ``inf``. DP at tolerance ``eps`` keeps
    exactly the vertices with ``sig > eps``.

    The 4-D form is what tiles thin CCS rows by (:mod:`engine.tiles.significance`): one chord parameter for both
    pairs. ``zw`` None compiles away (numba prunes the branches), so the plane keeps its own fast loop.
    """
    n = xy.shape[0]
    sig = np.zeros(n)
    if n == 0:
        return sig
    sig[0] = np.inf
    sig[n - 1] = np.inf
    stack_first = np.empty(n, np.int64)
    stack_last = np.empty(n, np.int64)
    stack_cap = np.empty(n)
    stack_first[0] = 0
    stack_last[0] = n - 1
    stack_cap[0] = np.inf
    top = 1
    az = aw = dz = dw = 0.0
    while top > 0:
        top -= 1
        first = stack_first[top]
        last = stack_last[top]
        cap = stack_cap[top]
        if last - first < 2:
            continue
        ax = xy[first, 0]
        ay = xy[first, 1]
        dx = xy[last, 0] - ax
        dy = xy[last, 1] - ay
        seg2 = dx * dx + dy * dy
        if zw is not None:
            az = zw[first, 0]
            aw = zw[first, 1]
            dz = zw[last, 0] - az
            dw = zw[last, 1] - aw
            # Summed one term at a time, in coordinate order, so every sum rounds as it always has.
            seg2 += dz * dz
            seg2 += dw * dw
        best = -1.0
        best_i = first + 1
        for i in range(first + 1, last):
            px = xy[i, 0] - ax
            py = xy[i, 1] - ay
            pz = pw = 0.0
            if zw is not None:
                pz = zw[i, 0] - az
                pw = zw[i, 1] - aw
            # Distance to the chord as a segment, so a vertex beyond an end still counts.
            u = 0.0
            if seg2 > 0.0:
                u = px * dx + py * dy
                if zw is not None:
                    u += pz * dz
                    u += pw * dw
                u /= seg2
                if u < 0.0:
                    u = 0.0
                elif u > 1.0:
                    u = 1.0
            qx = px - u * dx
            qy = py - u * dy
            d = qx * qx + qy * qy
            if zw is not None:
                qz = pz - u * dz
                qw = pw - u * dw
                d += qz * qz
                d += qw * qw
            if d > best:
                best = d
                best_i = i
        s = min(np.sqrt(best), cap)
        sig[best_i] = s
        stack_first[top] = first
        stack_last[top] = best_i
        stack_cap[top] = s
        top += 1
        stack_first[top] = best_i
        stack_last[top] = last
        stack_cap[top] = s
        top += 1
    return sig


@njit(cache=True)
def discrete_frechet(p: np.ndarray, q: np.ndarray, bound: float) -> float:  # pragma: no cover - compiled
    """Discrete Fréchet distance between two point sequences, exact, in O(len(p)) memory.

    ``bound`` is any known upper bound of the result (``inf`` if none). A cell whose own distance exceeds it
    cannot lie on an optimal coupling, so each row is only scanned between the first and last column that
    can still be reached below the bound: for two similar curves that is a narrow band along the diagonal
    and the cost is close to linear instead of quadratic.
    """
    n = p.shape[0]
    m = q.shape[0]
    inf = np.inf
    prev = np.full(m, inf)
    cur = np.full(m, inf)
    # A hair of slack so that the exact distance itself, squared with rounding, still counts as within bound.
    b2 = bound * bound * (1.0 + 1e-9) + 1e-18 if bound < inf else inf
    lo_prev = 0
    hi_prev = -1
    for i in range(n):
        px = p[i, 0]
        py = p[i, 1]
        lo = m
        hi = -1
        # Columns reachable in this row start at lo_prev (or 0 on the first row).
        start = lo_prev if i > 0 else 0
        for j in range(start, m):
            if i == 0:
                reach = cur[j - 1] if j > 0 else -1.0
                if j > 0 and reach == inf:
                    break
                best_prev = 0.0 if j == 0 else reach
            else:
                a = prev[j - 1] if j > 0 and j - 1 <= hi_prev and j - 1 >= lo_prev else inf
                b = prev[j] if j <= hi_prev and j >= lo_prev else inf
                c = cur[j - 1] if j > start else inf
                best_prev = min(a, min(b, c))
                if best_prev == inf:
                    if j > hi_prev + 1:
                        break
                    cur[j] = inf
                    continue
            dx = px - q[j, 0]
            dy = py - q[j, 1]
            d2 = dx * dx + dy * dy
            if d2 > b2:
                cur[j] = inf
                if j > hi_prev:
                    break
                continue
            val = max(d2, best_prev) if i > 0 or j > 0 else d2
            cur[j] = val
            if j < lo:
                lo = j
            hi = j
        # Clear the stale part of the previous row before swapping buffers.
        for j in range(lo_prev, min(hi_prev + 1, m)):
            prev[j] = inf
        if hi < 0:
            return inf
        prev, cur = cur, prev
        lo_prev = lo
        hi_prev = hi
    if hi_prev != m - 1:
        return inf
    return np.sqrt(prev[m - 1])
