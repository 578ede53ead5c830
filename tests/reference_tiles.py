"""Reference implementations the tests compare the compiled tile code with (shapely and mapbox_vector_tile)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.tiles.grid import drop_repeats
from engine.tiles.runs import CHUNK_ROWS
from engine.types import Bounds


def clip_to_grid(q: NDArray[np.int64], lo: int, hi: int) -> list[NDArray[np.int64]]:
    """Clip an integer polyline to the square [lo, hi]²; returns its pieces (each >= 2 distinct points).

    Lines wholly inside come back unchanged without touching shapely; the rest go through
    ``shapely.clip_by_rect`` and are rounded back to the grid.
    """
    if len(q) < 2:
        return []
    if q.min() >= lo and q.max() <= hi:
        return [q]
    mins = q.min(axis=0)
    maxs = q.max(axis=0)
    if mins[0] > hi or mins[1] > hi or maxs[0] < lo or maxs[1] < lo:
        return []
    clipped = shapely.clip_by_rect(shapely.linestrings(q.astype(np.float64)), lo, lo, hi, hi)
    pieces = []
    for part in shapely.get_parts(clipped):
        if shapely.get_type_id(part) != 1:  # a point where the line only touches the rectangle
            continue
        xy = drop_repeats(np.rint(shapely.get_coordinates(part)).astype(np.int64))
        if len(xy) >= 2:
            pieces.append(xy)
    return pieces


def row_runs(chunks: NDArray[np.float64], box: Bounds, m: int, size: int = CHUNK_ROWS) -> list[tuple[int, int]]:
    """Row ranges [a, b) of the chunks that meet ``box``, consecutive chunks merged."""
    hit = (
        (chunks[:, 2] >= box.minx)
        & (chunks[:, 0] <= box.maxx)
        & (chunks[:, 3] >= box.miny)
        & (chunks[:, 1] <= box.maxy)
    )
    if hit.all():
        return [(0, m)]
    idx = np.flatnonzero(hit)
    if len(idx) == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    firsts = np.concatenate([idx[:1], idx[cut + 1]])
    lasts = np.concatenate([idx[cut], idx[-1:]])
    return [(int(a) * size, min((int(b) + 1) * size + 1, m)) for a, b in zip(firsts, lasts, strict=True)]


def clip_lines(
    q: NDArray[np.int64], lens: NDArray[np.int64], lo: int, hi: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`clip_to_grid` of many concatenated integer polylines in one vectorised shapely call.

    Returns
    -------
    (pts, piece_lens, src)
        The pieces' points concatenated, each piece's length (>= 2) and the input line it comes from
        (pieces in input order).
    """
    empty = np.zeros(0, dtype=np.int64)
    if len(lens) == 0:
        return np.zeros((0, 2), dtype=np.int64), empty, empty
    geoms = shapely.linestrings(q.astype(np.float64), indices=np.repeat(np.arange(len(lens)), lens))
    clipped = shapely.clip_by_rect(geoms, lo, lo, hi, hi)
    parts, src = shapely.get_parts(clipped, return_index=True)
    is_line = shapely.get_type_id(parts) == 1
    parts, src = parts[is_line], src[is_line]
    if len(parts) == 0:
        return np.zeros((0, 2), dtype=np.int64), empty, empty
    xy, which = shapely.get_coordinates(parts, return_index=True)
    out = np.rint(xy).astype(np.int64)
    keep = np.ones(len(out), dtype=bool)
    keep[1:] = (out[1:, 0] != out[:-1, 0]) | (out[1:, 1] != out[:-1, 1]) | (which[1:] != which[:-1])
    out, which = out[keep], which[keep]
    counts = np.bincount(which, minlength=len(parts))
    good = counts >= 2
    if not good.all():
        out = out[good[which]]
        counts, src = counts[good], src[good]
    return out, counts.astype(np.int64), src.astype(np.int64)


def clip_many(lines: Sequence[NDArray[np.int64]], lo: int, hi: int) -> list[list[NDArray[np.int64]]]:
    """:func:`clip_to_grid` of many integer polylines in one vectorised shapely call; pieces per input line."""
    out: list[list[NDArray[np.int64]]] = [[] for _ in lines]
    if not lines:
        return out
    lens = np.fromiter((len(v) for v in lines), dtype=np.int64, count=len(lines))
    pts, counts, src = clip_lines(np.concatenate(lines), lens, lo, hi)
    starts = np.cumsum(counts) - counts
    for s, n, i in zip(starts.tolist(), counts.tolist(), src.tolist(), strict=True):
        out[i].append(pts[s : s + n])
    return out


def row_runs_many(
    chunks: Sequence[NDArray[np.float64]], sizes: Sequence[int], box: Bounds, size: int = CHUNK_ROWS
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`row_runs` of many lines at once: (line index, first row, end row) of every run."""
    counts = np.fromiter((len(c) for c in chunks), dtype=np.int64, count=len(chunks))
    allc = np.concatenate(chunks)
    owner = np.repeat(np.arange(len(chunks)), counts)
    offset = np.cumsum(counts) - counts
    hit = (allc[:, 2] >= box.minx) & (allc[:, 0] <= box.maxx) & (allc[:, 3] >= box.miny) & (allc[:, 1] <= box.maxy)
    idx = np.flatnonzero(hit)
    if len(idx) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    own = owner[idx]
    cut = np.flatnonzero((np.diff(idx) > 1) | (np.diff(own) != 0))
    firsts = np.concatenate([idx[:1], idx[cut + 1]])
    lasts = np.concatenate([idx[cut], idx[-1:]])
    lines = owner[firsts]
    m = np.asarray(sizes, dtype=np.int64)[lines]
    a = (firsts - offset[lines]) * size
    b = np.minimum((lasts - offset[lines] + 1) * size + 1, m)
    return lines, a, b
