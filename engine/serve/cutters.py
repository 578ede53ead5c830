"""Cutting a method's lines into a tile's parts, three ways: rounded (fast: thinned by significance, rounded a
point at a time), snapped (exact slices snap-rounded all together, so no two lines cross that do not), and
checked (rounded, cut again snapped where rounding made lines cross; docs/design.md section 4.8).

Every way starts from the runs of rows whose chunks meet the buffered tile (:func:`runs_meeting`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.serve.methods import TileLines
from engine.serve.tile_request import TileOptions
from engine.tiles.clip import clip_lines_exact, clip_lines_fast
from engine.tiles.crossings import lines_cross_in_grid
from engine.tiles.grid import buffered
from engine.tiles.runs import RunSet, ranges, slice_runs, slice_runs_exact
from engine.tiles.snap_round import snap_round
from engine.types import Bounds

#: Runs of rows [a, b) and the drawn contour each belongs to.
Runs = tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]


@dataclass(frozen=True)
class TileParts:
    """The quantised, clipped lines of a tile, feature by feature (before encoding).

    ``pts`` holds every part of every feature concatenated; ``part_len`` the points of each part and
    ``part_count`` the parts of each feature; ``owner`` is each feature's position in the contours drawn.
    """

    pts: NDArray[np.int64]
    part_len: NDArray[np.int64]
    part_count: NDArray[np.int64]
    owner: NDArray[np.int64]


def runs_meeting(drawn: TileLines, box: Bounds) -> Runs | None:
    """Runs of rows [a, b) of the drawn lines whose chunks meet ``box`` (consecutive chunks merged), with the
    contour each run belongs to (runs grouped by contour, in line order); None when no chunk meets it."""
    lines = drawn.lines
    which = drawn.which
    c_lo, c_hi = lines.chunk_off[which], lines.chunk_off[which + 1]
    ci = ranges(c_lo, c_hi)
    ch = lines.chunks[ci]
    hit = (ch[:, 2] >= box.minx) & (ch[:, 0] <= box.maxx) & (ch[:, 3] >= box.miny) & (ch[:, 1] <= box.maxy)
    h = np.flatnonzero(hit)
    if len(h) == 0:
        return None
    owner_of_chunk = np.repeat(np.arange(len(which)), c_hi - c_lo)
    hc, own = ci[h], owner_of_chunk[h]
    cut = np.flatnonzero((np.diff(hc) != 1) | (np.diff(own) != 0))
    first = np.concatenate([[0], cut + 1])
    last = np.concatenate([cut, [len(h) - 1]])
    run_owner = own[first]
    c = which[run_owner]
    row0 = lines.off[c]
    size = lines.chunk_rows
    a = row0 + (hc[first] - lines.chunk_off[c]) * size
    b = np.minimum(row0 + (hc[last] - lines.chunk_off[c] + 1) * size + 1, lines.off[c + 1])
    return a, b, run_owner


class TileCutter:
    """The three cuts of a tile grid (``options``: extent, buffer, whether snap rounding is on)."""

    def __init__(self, options: TileOptions) -> None:
        self.options = options

    def min_significance(self, box: Bounds) -> float:
        """Rows less significant than half a grid unit cannot move the quantised line (tiles.significance)."""
        return 0.5 * (box.maxx - box.minx) / (self.options.extent + 2 * self.options.buffer_px)

    def cut(self, drawn: TileLines, bounds: Bounds, box: Bounds, snap: bool = True) -> TileParts | None:
        """The tile pipeline after the method: runs of rows that meet ``box``, sliced, thinned, quantised,
        clipped to the buffered tile; None when nothing is left.

        Plain rounding and thinning can make two lines closer than a grid unit cross; a tile where they do is
        cut again by snap rounding, which cannot (:meth:`cut_snapped`, docs/design.md section 4.8); ``snap`` False
        leaves the tile as rounded (a method whose lines cross by themselves).
        """
        runs = runs_meeting(drawn, box)
        if runs is None:
            return None
        parts = self.cut_rounded(drawn, runs, bounds)
        if parts is not None and snap and self.options.snap_rounding:
            if lines_cross_in_grid(parts.pts, parts.part_len, np.repeat(parts.owner, parts.part_count)):
                return self.cut_snapped(drawn, runs, bounds)
        return parts

    def cut_snapped(self, drawn: TileLines, runs: Runs, bounds: Bounds) -> TileParts | None:
        """Every row of the runs sliced exactly, clipped to the buffered tile, then snap-rounded all together
        (:mod:`engine.tiles.snap_round`): no two lines cross properly unless their exact slices do. Rows are
        thinned only where they collapse into one grid point."""
        opts = self.options
        a, b, run_owner = runs
        lines = drawn.lines
        pts, plen = slice_runs_exact(a, b, drawn.slice_t[run_owner], lines, bounds, opts.extent)
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        c_pts, c_len, c_src = clip_lines_exact(pts, plen, lo, hi)
        q, q_len, q_src = snap_round(c_pts, c_len)
        if len(q_len) == 0:
            return None
        part_owner = run_owner[c_src[q_src]]
        order = np.argsort(part_owner, kind="stable")
        q_start = np.cumsum(q_len) - q_len
        part_len = q_len[order]
        out = q[ranges(q_start[order], q_start[order] + part_len)]
        owners, counts = np.unique(part_owner, return_counts=True)
        return TileParts(out, part_len, counts, owners)

    def cut_rounded(self, drawn: TileLines, runs: Runs, bounds: Bounds) -> TileParts | None:
        """Runs sliced, thinned by significance and rounded to the grid one point at a time, then clipped.

        Every step runs over all the tile's lines at once; only the pieces crossing the buffered tile's edge
        are clipped.
        """
        opts = self.options
        lines = drawn.lines
        a, b, run_owner = runs
        box = buffered(bounds, opts.buffer_px, opts.extent)
        q, plen, pbox = slice_runs(
            RunSet(a, b, drawn.column[run_owner], drawn.refill[run_owner]),
            drawn.slice_t[run_owner],
            lines,
            self.min_significance(box),
            bounds,
            opts.extent,
        )
        lo, hi = -opts.buffer_px, opts.extent + opts.buffer_px
        pstart = np.cumsum(plen) - plen
        inside = (pbox[:, 0] >= lo) & (pbox[:, 1] >= lo) & (pbox[:, 2] <= hi) & (pbox[:, 3] <= hi)
        valid = plen >= 2
        k_in = np.flatnonzero(valid & inside)
        k_cross = np.flatnonzero(valid & ~inside)
        if len(k_cross):
            cross_pts = q[ranges(pstart[k_cross], pstart[k_cross] + plen[k_cross])]
            c_pts, c_len, c_src = clip_lines_fast(cross_pts, plen[k_cross], lo, hi)
            k_clip = k_cross[c_src]
        else:
            c_pts, c_len, k_clip = np.zeros((0, 2), dtype=np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        if len(k_in) + len(k_clip) == 0:
            return None
        # Parts of a feature: its pieces wholly inside, then the clipped ones, each in line order.
        part_owner = np.concatenate([run_owner[k_in], run_owner[k_clip]])
        part_group = np.concatenate([np.zeros(len(k_in), np.int8), np.ones(len(k_clip), np.int8)])
        part_start = np.concatenate([pstart[k_in], len(q) + np.cumsum(c_len) - c_len])
        part_len = np.concatenate([plen[k_in], c_len])
        order = np.lexsort((part_group, part_owner))
        part_owner, part_start, part_len = part_owner[order], part_start[order], part_len[order]
        all_pts = np.concatenate([q, c_pts]) if len(c_pts) else q
        pts = all_pts[ranges(part_start, part_start + part_len)]
        owners, counts = np.unique(part_owner, return_counts=True)
        return TileParts(pts, part_len, counts, owners)
