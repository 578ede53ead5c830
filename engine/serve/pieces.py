"""A tile's pack of a dataset too large to hold in memory, read from the stored pieces of the contours' rows.

Each contour's CCS rows and original rows are stored whole and also in pieces of
:data:`~engine.store.schema.PIECE_ROWS` rows with their own boxes in an R*Tree per kind. A tile reads only the
pieces that meet the buffered tile, of the one kind its method draws, and joins each contour's pieces into one
line. A piece starts on a chunk boundary of the whole line and ends on the next chunk's first row, so the joined
line's chunks (their rows and boxes) are the whole line's chunks; where pieces were left out between two read
ones, one chunk of filler rows (NaN, whose box meets nothing) keeps the runs apart and the chunks aligned. The
tile thus meets the same chunks, slices the same runs of rows, and is byte for byte the tile of the whole lines.
The tile's contours are those with a piece that meets it: one whose box meets the tile while none of its
pieces does would draw nothing there, so the pieces' R*Tree is the only one a tile asks. A contour without
rows in its pack (the baselines draw from whole decoded contours) gets a stand-in line of filler that meets no
box.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.serve.heads import DatasetHeads, read_heads
from engine.serve.pack import DatasetPack, LineSet
from engine.store.records import StoredPieces
from engine.store.schema import PIECE_KINDS, PIECE_ROWS
from engine.store.store import CCSStore
from engine.tiles.runs import CHUNK_ROWS
from engine.types import Bounds

assert PIECE_ROWS % CHUNK_ROWS == 0, "a stored piece must hold whole chunks of the tiles' spatial index"

#: Filler rows after a piece followed by a gap: the shared row is kept, so these bring the next piece onto a
#: chunk boundary.
FILLER_ROWS = CHUNK_ROWS - 1
#: Rows of the stand-in line of a contour none of whose pieces was read.
STAND_IN_ROWS = 2


def joined(pieces: StoredPieces, fids: NDArray[np.int64]) -> tuple[tuple[NDArray[Any], ...], NDArray[np.int64]]:
    """Each contour's pieces joined into one line, the lines in the order of ``fids`` (sorted): every column's
    rows, and the rows of each line.

    Consecutive pieces share a row, kept once; after a piece followed by a gap, filler rows bring the next piece
    onto a chunk boundary; a contour of ``fids`` without pieces gets a stand-in line of filler. Filler is NaN
    coordinates (any comparison with NaN is false, so its box meets nothing) and zero significance.
    """
    fids = np.asarray(fids, dtype=np.int64)
    start = np.cumsum(pieces.n) - pieces.n
    sizes = np.zeros(len(fids), dtype=np.int64)
    # Room for every stored row, filler after every piece and a stand-in for every contour; the walk uses less.
    room = int(pieces.n.sum()) + FILLER_ROWS * len(pieces.n) + STAND_IN_ROWS * len(fids)
    take = np.empty(room, dtype=np.int64)
    used = _rows_taken(pieces.fid, pieces.k, pieces.n, start, fids, take, sizes)
    columns = tuple(_gathered(c, take[:used]) for c in pieces.columns)
    return columns, sizes


def _gathered(column: NDArray[Any], take: NDArray[np.int64]) -> NDArray[Any]:
    """Rows ``take`` of a column, -1 standing for a filler row."""
    out = np.empty((len(take), *column.shape[1:]), dtype=column.dtype)
    if column.ndim == 2:
        _gather_rows(column, take, out)
    else:
        _gather_values(column, take, out)
    return out


@njit(cache=True)
def _rows_taken(fid, k, n, start, fids, take, sizes):  # pragma: no cover - compiled
    """The stored row behind each row of the joined lines (-1: filler) into ``take``, the rows of each line into
    ``sizes``; returns how many rows ``take`` holds (pieces sorted by fid and k; ``fids`` sorted; pieces of other
    fids skipped)."""
    i = 0
    w = 0
    for j in range(len(fids)):
        line_start = w
        while i < len(fid) and fid[i] < fids[j]:
            i += 1
        if i == len(fid) or fid[i] != fids[j]:
            for _ in range(STAND_IN_ROWS):
                take[w] = -1
                w += 1
        while i < len(fid) and fid[i] == fids[j]:
            keep, fill = n[i], 0
            if i + 1 < len(fid) and fid[i + 1] == fid[i]:
                if k[i + 1] == k[i] + 1:
                    keep -= 1  # the next piece starts with this one's last row
                else:
                    fill = FILLER_ROWS
            for r in range(keep):
                take[w] = start[i] + r
                w += 1
            for _ in range(fill):
                take[w] = -1
                w += 1
            i += 1
        sizes[j] = w - line_start
    return w


@njit(cache=True)
def _gather_rows(column, take, out):  # pragma: no cover - compiled
    for w in range(len(take)):
        if take[w] < 0:
            out[w, 0] = np.nan
            out[w, 1] = np.nan
        else:
            out[w, 0] = column[take[w], 0]
            out[w, 1] = column[take[w], 1]


@njit(cache=True)
def _gather_values(column, take, out):  # pragma: no cover - compiled
    for w in range(len(take)):
        out[w] = 0 if take[w] < 0 else column[take[w]]


def _nowhere(kind: str) -> StoredPieces:
    """No piece of any contour (every line a stand-in)."""
    empty = tuple(np.zeros(0, np.float32) if c.startswith("sig") else np.zeros((0, 2)) for c in PIECE_KINDS[kind])
    none = np.zeros(0, np.int64)
    return StoredPieces(none, none, none, empty)


def pack_of_pieces(
    store: CCSStore,
    dataset: str,
    box: Bounds,
    data_version: int,
    interval: float | None,
    kind: str | None,
    heads: DatasetHeads | None = None,
) -> DatasetPack | None:
    """The pack of the contours whose rows of ``kind`` (``ccs`` or ``original``) meet ``box``, holding only the
    pieces that do; for ``kind`` None (a method that draws from whole decoded contours), of the contours whose
    box meets ``box``, holding none of their rows. None when there is no such contour.

    A contour whose box meets ``box`` while none of its pieces does would draw nothing in the tile, so the
    pieces' own R*Tree is the only one a tile of stored pieces asks. The contours' heads come from ``heads``
    (the dataset's, held in memory) when given, else from the store; so do the bounds of the dataset's fids, by
    which its pieces are told apart from other datasets' when they are one run of fids.
    """
    fid_range = None if heads is None else heads.fid_range
    read = {
        each: store.pieces_meeting(dataset, box, each, fid_range) if each == kind else _nowhere(each)
        for each in PIECE_KINDS
    }
    fids = store.query(dataset, box) if kind is None else np.unique(read[kind].fid).tolist()
    if not fids:
        return None
    columns = read_heads(store, fids) if heads is None else heads.of(store, fids)
    lines = {each: joined(pieces, columns.fid) for each, pieces in read.items()}
    (base, top, sig, sig_top), ccs_sizes = lines["ccs"]
    (original, sig_original), original_sizes = lines["original"]
    ccs = LineSet.of(base, top, ccs_sizes, np.column_stack([sig, sig_top]))
    return DatasetPack.of_lines(
        data_version, columns, ccs, LineSet.of(original, original, original_sizes, sig_original), interval
    )
