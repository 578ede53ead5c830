"""How straight a contour runs under a label, at every zoom of its candidates, compiled (numba).

A label candidate needs the line straight over the label's length centred at the row, at every zoom from its
first on (engine.cartography.labels.contour_candidates). Measured with NumPy that was a dozen calls per zoom
and contour, a twentieth of a whole build; here it is one pass per contour doing the same arithmetic in the
same order (``np.interp``'s rule included), so the candidates are the same to the last bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def straightness_at_zooms(base, top, ts, widths):  # pragma: no cover - compiled
    """``(ratio, inside)``, each (K, M): for the line ``(1 - ts[k]) base + ts[k] top`` and each of its M rows,
    chord / arc over ``widths[k]`` metres of line centred at the row (the window's ends clamped to the line and
    interpolated along it), and whether the window lies wholly on the line."""
    n_zooms = ts.shape[0]
    m = base.shape[0]
    ratio = np.empty((n_zooms, m))
    inside = np.empty((n_zooms, m), dtype=np.bool_)
    line = np.empty((m, 2))
    s = np.empty(m)
    for k in range(n_zooms):
        t = ts[k]
        for i in range(m):
            for c in range(2):
                line[i, c] = (1 - t) * base[i, c] + t * top[i, c]
        s[0] = 0.0
        for i in range(1, m):
            s[i] = s[i - 1] + np.hypot(line[i, 0] - line[i - 1, 0], line[i, 1] - line[i - 1, 1])
        end = s[m - 1]
        half = widths[k] / 2
        # Both window ends only move forward along the line from row to row: each finds its segment by walking
        # on from where it was, not by a search.
        ja = 0
        jb = 0
        for i in range(m):
            inside[k, i] = s[i] - half >= 0 and s[i] + half <= end
            a = min(max(s[i] - half, 0.0), end)
            b = min(max(s[i] + half, 0.0), end)
            ja = _last_at_or_before(s, a, ja)
            jb = _last_at_or_before(s, b, jb)
            ax, ay = _at(s, line, a, ja)
            bx, by = _at(s, line, b, jb)
            ratio[k, i] = np.hypot(bx - ax, by - ay) / max(b - a, 1e-9)
    return ratio, inside


@njit(cache=True)
def _last_at_or_before(s, x, j):  # pragma: no cover - compiled
    """The last row whose arc length is at most ``x`` (the row ``np.interp`` interpolates from), from ``j`` on."""
    while j + 1 < s.shape[0] and s[j + 1] <= x:
        j += 1
    return j


@njit(cache=True)
def _at(s, line, x, j):  # pragma: no cover - compiled
    """The point of ``line`` at arc length ``x`` (within ``s[0]``..``s[-1]``; ``j`` the last row at or before it), by
    ``np.interp``'s rule: its own point when ``x`` is on the row, the slope's other end if the first form is NaN."""
    m = s.shape[0]
    if j >= m - 1 or s[j] == x:
        return line[j, 0], line[j, 1]
    out = np.empty(2)
    for c in range(2):
        slope = (line[j + 1, c] - line[j, c]) / (s[j + 1] - s[j])
        v = slope * (x - s[j]) + line[j, c]
        if np.isnan(v):
            v = slope * (x - s[j + 1]) + line[j + 1, c]
            if np.isnan(v) and line[j, c] == line[j + 1, c]:
                v = line[j, c]
        out[c] = v
    return out[0], out[1]
