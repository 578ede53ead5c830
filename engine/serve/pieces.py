"""A tile's pack of a dataset too large to hold in memory, read from the stored pieces of the contours' rows.

Each contour's CCS rows and original rows are stored whole and also in pieces of
:data:`~engine.store.sqlite.PIECE_ROWS` rows with their own boxes in an R*Tree per kind. A tile reads only the
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
from numpy.typing import NDArray

from engine.serve.heads import DatasetHeads, read_heads
from engine.serve.pack import DatasetPack, LineSet
from engine.store.sqlite import PIECE_KINDS, PIECE_ROWS, CCSStore, StoredPieces
from engine.tiles.runs import CHUNK_ROWS, ranges
from engine.types import Bounds

assert PIECE_ROWS % CHUNK_ROWS == 0, "a stored piece must hold whole chunks of the tiles' spatial index"

#: Filler rows after a piece followed by a gap: the shared row is kept, so these bring the next piece onto a
#: chunk boundary.
FILLER_ROWS = CHUNK_ROWS - 1
#: Rows of the stand-in line of a contour none of whose pieces was read.
STAND_IN_ROWS = 2


def _with_filler(column: NDArray[Any]) -> NDArray[Any]:
    """A column followed by FILLER_ROWS rows that meet no box: NaN coordinates (any comparison with NaN is
    false), zero significance."""
    shape = (FILLER_ROWS, *column.shape[1:])
    filler = np.full(shape, np.nan) if column.ndim == 2 else np.zeros(shape, column.dtype)
    return np.concatenate([column, filler])


def joined(pieces: StoredPieces, fids: NDArray[np.int64]) -> tuple[tuple[NDArray[Any], ...], NDArray[np.int64]]:
    """Each contour's pieces joined into one line, the lines in the order of ``fids`` (sorted): every column's
    rows, and the rows of each line.

    Consecutive pieces share a row, kept once; after a piece followed by a gap, filler rows bring the next piece
    onto a chunk boundary; a contour of ``fids`` without pieces gets a stand-in line of filler.
    """
    mine = np.isin(pieces.fid, fids)
    fid, k, n = pieces.fid[mine], pieces.k[mine], pieces.n[mine]
    start = (np.cumsum(pieces.n) - pieces.n)[mine]
    filler_at = int(pieces.n.sum())  # the first filler row, after every stored row
    same_next = np.zeros(len(fid), dtype=bool)
    same_next[:-1] = fid[1:] == fid[:-1]
    follows = np.zeros(len(fid), dtype=bool)
    follows[:-1] = k[1:] == k[:-1] + 1
    keep = n - (same_next & follows)
    filler = np.where(same_next & ~follows, FILLER_ROWS, 0)
    missing = fids[~np.isin(fids, fid)]
    # Each entry (a piece or a stand-in) is two ranges of rows: its own rows, then filler rows.
    entry_fid = np.concatenate([fid, missing])
    a = np.concatenate([start, np.full(len(missing), filler_at)])
    b = a + np.concatenate([keep, np.full(len(missing), STAND_IN_ROWS)])
    fill = np.concatenate([filler, np.zeros(len(missing), np.int64)])
    order = np.argsort(entry_fid, kind="stable")
    a, b, fill = a[order], b[order], fill[order]
    starts = np.column_stack([a, np.full(len(a), filler_at)]).ravel()
    ends = np.column_stack([b, filler_at + fill]).ravel()
    take = ranges(starts, ends)
    sizes = np.bincount(np.searchsorted(fids, entry_fid[order]), weights=b - a + fill, minlength=len(fids))
    columns = tuple(_with_filler(c)[take] for c in pieces.columns)
    return columns, sizes.astype(np.int64)


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
    (the dataset's, held in memory) when given, else from the store.
    """
    read = {each: store.pieces_meeting(dataset, box, each) if each == kind else _nowhere(each) for each in PIECE_KINDS}
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
