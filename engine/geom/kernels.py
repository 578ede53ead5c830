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

    Both row buffers hold ``inf`` outside the band last written (a row's band is cleared before its buffer is
    reused), so a cell reads its three neighbours without range checks: the band's cells are most of the
    build's similarity tables, and the checks were half their time.
    """
    n = p.shape[0]
    m = q.shape[0]
    inf = np.inf
    prev = np.full(m, inf)
    cur = np.full(m, inf)
    # A hair of slack so that the exact distance itself, squared with rounding, still counts as within bound.
    b2 = bound * bound * (1.0 + 1e-9) + 1e-18 if bound < inf else inf
    # Row 0: the running maximum along q, up to the first cell beyond the bound.
    hi_prev = -1
    run = 0.0
    for j in range(m):
        dx = p[0, 0] - q[j, 0]
        dy = p[0, 1] - q[j, 1]
        d2 = dx * dx + dy * dy
        if d2 > b2:
            break
        run = max(run, d2)
        cur[j] = run
        hi_prev = j
    if hi_prev < 0:
        return inf
    lo_prev = 0
    prev, cur = cur, prev
    for i in range(1, n):
        px = p[i, 0]
        py = p[i, 1]
        lo = m
        hi = -1
        left = inf  # this row's cell j - 1
        diag = prev[lo_prev - 1] if lo_prev > 0 else inf  # the previous row's cell j - 1
        for j in range(lo_prev, m):
            up = prev[j]
            best = min(left, min(up, diag))
            diag = up
            if best == inf:
                if j > hi_prev:
                    break  # nothing to the right can be reached any more
                cur[j] = inf
                left = inf
                continue
            dx = px - q[j, 0]
            dy = py - q[j, 1]
            d2 = dx * dx + dy * dy
            if d2 > b2:
                cur[j] = inf
                left = inf
                if j > hi_prev:
                    break
                continue
            left = max(d2, best)
            cur[j] = left
            if lo == m:
                lo = j
            hi = j
        # Clear the previous row's band before its buffer becomes the next row.
        for j in range(lo_prev, hi_prev + 1):
            prev[j] = inf
        if hi < 0:
            return inf
        prev, cur = cur, prev
        lo_prev = lo
        hi_prev = hi
    if hi_prev != m - 1:
        return inf
    return np.sqrt(prev[m - 1])


#: Rounding of a sum of n float64 terms, in any order, relative to the sum of their magnitudes: at most
#: (n - 1) units of 2**-53 each way; twice that, and twice again, covers the two sums a shoelace area takes.
_SUM_ROUNDING = 4.0 * 2.0**-53


@njit(cache=True)
def first_small_slice(base, top, ts, thresholds):  # pragma: no cover - compiled
    """The first k whose ring slice ``(1 - ts[k]) base + ts[k] top`` ((M, 2) rows, the ring without its repeated
    first vertex) has a shoelace area below ``thresholds[k]``; -1 if none has; -2 if, before the first small one,
    an area is too close to its threshold for this pass to tell.

    The slices are made, and taken relative to their first vertex, as ``engine.geom.polyline.ring_areas`` makes
    them; its sums go in NumPy's own order, these in another, so a verdict counts only when the area clears its
    threshold by more than both sums' rounding could move it. Stops at the first small slice.
    """
    m = base.shape[0]
    for k in range(ts.shape[0]):
        t = ts[k]
        x0 = (1.0 - t) * base[0, 0] + t * top[0, 0]
        y0 = (1.0 - t) * base[0, 1] + t * top[0, 1]
        xa = 0.0
        ya = 0.0
        xy = 0.0
        yx = 0.0
        size = 0.0
        for i in range(1, m):
            xb = ((1.0 - t) * base[i, 0] + t * top[i, 0]) - x0
            yb = ((1.0 - t) * base[i, 1] + t * top[i, 1]) - y0
            xy += xa * yb
            yx += ya * xb
            size += abs(xa * yb) + abs(ya * xb)
            xa = xb
            ya = yb
        area = abs(xy - yx) / 2.0
        margin = m * _SUM_ROUNDING * size + 1e-300
        if area < thresholds[k] - margin:
            return k
        if not area > thresholds[k] + margin:
            return -2
    return -1


@njit(cache=True)
def path_fault(xy, closed):  # pragma: no cover - compiled
    """What first makes (n, 2) ``xy`` unusable as a contour's path: 1 a NaN or infinite coordinate, 2 two
    consecutive vertices at the same point (for a ring, the last and the first too), 0 neither."""
    n = xy.shape[0]
    for i in range(n):
        if not (np.isfinite(xy[i, 0]) and np.isfinite(xy[i, 1])):
            return 1
    for i in range(1, n):
        if xy[i, 0] == xy[i - 1, 0] and xy[i, 1] == xy[i - 1, 1]:
            return 2
    if closed and n > 1 and xy[0, 0] == xy[n - 1, 0] and xy[0, 1] == xy[n - 1, 1]:
        return 2
    return 0


@njit(cache=True)
def numpy_sum(a):  # pragma: no cover - compiled
    """``a.sum()`` of a contiguous float64 array, to the last bit: NumPy's own order (pairwise: halves split at
    multiples of 8 down to blocks of at most 128, each summed in eight running sums), from its identity 0.0.

    The halves are walked with a stack of their own: a recursive kernel crashed when loaded from numba's cache.
    """
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)
    sums = np.empty(64)
    top = 0
    done = 0
    los[0] = 0
    ns[0] = a.shape[0]
    while top >= 0:
        lo, n = los[top], ns[top]
        if n <= 128:
            sums[done] = _block_sum(a, lo, n)
            done += 1
            top -= 1
        elif stage[top] < 2:  # first the lower half, then the upper one
            half = n // 2
            half -= half % 8
            stage[top] += 1
            los[top + 1] = lo if stage[top] == 1 else lo + half
            ns[top + 1] = half if stage[top] == 1 else n - half
            stage[top + 1] = 0
            top += 1
        else:
            done -= 1
            sums[done - 1] = sums[done - 1] + sums[done]
            top -= 1
    return 0.0 + sums[0]


@njit(cache=True)
def _block_sum(a, lo, n):  # pragma: no cover - compiled
    """NumPy's sum of at most 128 values: in order below 8, else eight running sums combined pairwise, then the
    rest in order."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r = a[lo : lo + 8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def path_length_of(xy, closed):  # pragma: no cover - compiled
    """Length of (n, 2) ``xy`` (a ring with its closing step), as ``np.hypot`` of its steps summed by NumPy."""
    n = xy.shape[0]
    steps = n if closed and n > 0 else max(n - 1, 0)
    lengths = np.empty(steps)
    for i in range(steps):
        j = i + 1 if i + 1 < n else 0
        lengths[i] = np.hypot(xy[j, 0] - xy[i, 0], xy[j, 1] - xy[i, 1])
    return numpy_sum(lengths)


@njit(cache=True)
def resampled(xy, count):  # pragma: no cover - compiled
    """``count`` >= 2 points equally spaced along (n >= 1, 2) ``xy``, both ends included: the arc length by
    ``np.hypot`` and a running sum, the targets as ``np.linspace(0, length, count)`` makes them, each point by
    ``np.interp``'s rule (the last row at or before it, its own point on a row, NaN's fallbacks)."""
    n = xy.shape[0]
    cum = np.empty(n)
    cum[0] = 0.0
    for i in range(1, n):
        cum[i] = cum[i - 1] + np.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1])
    total = cum[n - 1]
    step = total / (count - 1)
    out = np.empty((count, 2))
    j = 0
    for i in range(count):
        if i == count - 1:
            x = total
        elif step == 0.0:  # np.linspace's way for a step that underflows
            x = i / (count - 1) * total + 0.0
        else:
            x = i * step + 0.0
        while j + 1 < n and cum[j + 1] <= x:
            j += 1
        for c in range(2):
            if j == n - 1 or cum[j] == x:
                v = xy[j, c]
            else:
                slope = (xy[j + 1, c] - xy[j, c]) / (cum[j + 1] - cum[j])
                v = slope * (x - cum[j]) + xy[j, c]
                if np.isnan(v):
                    v = slope * (x - cum[j + 1]) + xy[j + 1, c]
                    if np.isnan(v) and xy[j, c] == xy[j + 1, c]:
                        v = xy[j, c]
            out[i, c] = v
    return out


@njit(cache=True)
def ring_significance(xy):  # pragma: no cover - compiled
    """Douglas–Peucker significance of every vertex of a ring of n >= 4 vertices (``xy`` without its repeated
    first vertex), as ``engine.geom.douglas_peucker.significance`` defines it: split at two far apart vertices
    (the farthest from the first, then the farthest from that), each half's ``dp_significance``, the anchors
    and the most significant other vertex ``inf`` (the minimal triangle)."""
    n = xy.shape[0]
    a, b = ring_anchor_pair(xy)
    second = np.empty((n - b + a + 1, 2))
    second[: n - b] = xy[b:]
    second[n - b :] = xy[: a + 1]
    sig = np.empty(n)
    sig[a : b + 1] = dp_significance(xy[a : b + 1].copy())
    sig2 = dp_significance(second)
    for k in range(second.shape[0]):
        sig[(b + k) % n] = sig2[k]
    sig[a] = np.inf
    sig[b] = np.inf
    best = -1
    for i in range(n):
        if np.isfinite(sig[i]) and (best < 0 or sig[i] > sig[best]):
            best = i
    if best >= 0:
        sig[best] = np.inf
    return sig


@njit(cache=True)
def ring_anchor_pair(xy):  # pragma: no cover - compiled
    """Two far apart vertices ``a < b`` of a ring of n >= 2 vertices, where it is split for Douglas–Peucker: the
    vertex farthest from the first, then the vertex farthest from that one (the next one if all coincide)."""
    a = _farthest_from(xy, 0)
    b = _farthest_from(xy, a)
    if a == b:  # every vertex is the same point
        b = (a + 1) % xy.shape[0]
    return (a, b) if a < b else (b, a)


@njit(cache=True)
def _farthest_from(xy, origin):  # pragma: no cover - compiled
    """The first vertex of the largest squared distance from vertex ``origin`` (``np.argmax``'s choice: the
    first NaN, if any)."""
    best = 0
    far = -1.0
    for i in range(xy.shape[0]):
        dx = xy[i, 0] - xy[origin, 0]
        dy = xy[i, 1] - xy[origin, 1]
        d = dx * dx + dy * dy
        if np.isnan(d):
            return i
        if d > far:
            far = d
            best = i
    return best
