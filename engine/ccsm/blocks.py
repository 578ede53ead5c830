"""Spatial blocks for the crossing repair: each block's contours are checked against the stretches of other
contours that can reach them, not against the whole set (docs/design.md section 4.8, issue 12 item 2).

Every surface is cut into pieces of :data:`INDEX_PIECE_SEGMENTS` segments, and each piece has a swept box: the
box of its rows at t = 0 and t = 1, which holds its slices at every t. A piece belongs to the block of a
square grid that holds its box centre, and a block's *own* stretches are its runs of consecutive pieces. Its
*near* stretches are, of every contour, the runs of consecutive pieces whose boxes meet an own piece's box:
the only rows whose slices can meet the own stretches. Checking each block's own stretches against its near
ones therefore finds exactly the meeting pairs of contours a check of the whole set finds (each meeting
point from the block of either piece), so the repair's decisions do not change, and no block's work grows
with the longest contour. The piece boxes stay in memory
(a few numbers per 16 rows); a block's surfaces are read from the spool only when its check is sent, so
blocks are checked apart from each other, on any executor, with memory for a few blocks at a time.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.near import boxes_meeting
from engine.ccsm.spool import Spool, surface_of
from engine.ccsm.topology import (
    InputTouches,
    SurfaceRows,
    concatenated_ranges,
    new_contact_pairs,
    pairs_touching,
    per_piece,
    piece_ranges,
)
from engine.heap import release_free_memory
from engine.parallel import map_ordered
from engine.payloads import FileSlice, fetched, opened
from engine.types import Coords

if TYPE_CHECKING:
    from engine.ccsm.ccs import CCS

#: Contours per block on average: large enough that a block's check is worth a task, small enough that its
#: surfaces are a small share of a big build's memory.
BLOCK_CONTOURS = 1024

#: Rows (about) per block: bounds a block's work and its worker's memory when contours are long.
BLOCK_ROWS = 1 << 17

#: Rebuilt contours per block when only they are checked again: small blocks keep each check to the rebuilt
#: contours' surroundings, but blocks of 16 read and cut their shared neighbours again and again on dense data.
REBUILT_PER_BLOCK = 64

#: Segments per piece of the blocks' index: short enough that a contour passing by a block is cut close to the
#: block, long enough that the index is a small fraction of the rows.
INDEX_PIECE_SEGMENTS = 16


class PieceIndex:
    """The swept boxes of every surface's pieces, by surface number; a rebuilt surface's pieces replace its old
    ones (:meth:`put`).

    A big set has a million pieces, so they are kept compact: float32 boxes rounded outward (a box may grow by
    a float32 step, half a metre at UTM coordinates, which only adds candidates; it never loses one), int32
    rows and owners, 28 bytes a piece. Each :meth:`put` adds a segment of pieces; :meth:`arrays` merges the
    segments into one owner-sorted array, leaving out replaced pieces, only when asked.

    >>> from engine.ccsm.ccs import CCS
    >>> line = np.column_stack([np.arange(40.0), np.zeros(40)])
    >>> index = PieceIndex()
    >>> index.put([0], [CCS("a", 1.0, False, line, line + [0, 2], np.zeros(1), np.ones(1), 39.0, 40, 40)])
    >>> index.arrays()[0].tolist()  # (minx, miny, maxx, maxy) of segments 0-16, 16-32, 32-39
    [[0.0, 0.0, 16.0, 2.0], [16.0, 0.0, 32.0, 2.0], [32.0, 0.0, 39.0, 2.0]]
    """

    def __init__(self) -> None:
        # Segments of (boxes (k, 4) float32, first (k,) int32, last (k,) int32, owner (k,) int32), the first
        # one the merged pieces of every earlier segment.
        self._segments: list[tuple[NDArray[np.float32], NDArray[np.int32], NDArray[np.int32], NDArray[np.int32]]]
        self._segments = []
        self._version = np.zeros(0, dtype=np.int32)  # how many times each surface was put
        self._stale = 0  # pieces of replaced surfaces still in the segments

    def put(self, numbers: Sequence[int], surfaces: Sequence[CCS]) -> None:
        """Index ``surfaces`` as numbers ``numbers`` (one vectorised pass for them all)."""
        self.put_boxes(numbers, piece_boxes(surfaces))

    def put_boxes(self, numbers: Sequence[int], boxes: PieceBoxes) -> None:
        """Index the pieces of surfaces, found by :func:`piece_boxes` (where they were built), as ``numbers``."""
        if not len(numbers):
            return
        numbers_arr = np.asarray(numbers, dtype=np.int32)
        top_number = int(numbers_arr.max()) + 1
        if top_number > len(self._version):
            self._version = np.concatenate([self._version, np.zeros(top_number - len(self._version), np.int32)])
        self._stale += int(np.count_nonzero(self._version[numbers_arr]))  # their old pieces are left out later
        self._version[numbers_arr] += 1
        self._segments.append((boxes.boxes, boxes.first, boxes.last, numbers_arr[boxes.owner]))

    def arrays(
        self,
    ) -> tuple[NDArray[np.float32], NDArray[np.int32], NDArray[np.int32], NDArray[np.int32], NDArray[np.intp]]:
        """(boxes (P, 4), first row, last row, owner, start) of every piece, sorted by owner; ``start[i]`` is
        the first piece of surface i (``start`` has one more entry, the number of pieces)."""
        if len(self._segments) > 1 or self._stale:
            self._merge()
        if not self._segments:
            empty = np.zeros(0, dtype=np.int32)
            return np.zeros((0, 4), np.float32), empty, empty, empty, np.zeros(1, dtype=np.intp)
        boxes, first, last, owner = self._segments[0]
        counts = np.bincount(owner + 1, minlength=int(owner[-1]) + 2) if len(owner) else np.zeros(1, np.intp)
        return boxes, first, last, owner, np.cumsum(counts).astype(np.intp)

    def _merge(self) -> None:
        """One owner-sorted segment of the latest pieces of each surface (a surface's latest segment wins)."""
        owners = np.concatenate([seg[3] for seg in self._segments])
        # Each piece's segment; a surface's pieces of an older segment than its latest are replaced ones.
        segment_of = np.repeat(np.arange(len(self._segments)), [len(seg[3]) for seg in self._segments])
        latest = np.zeros(len(self._version), dtype=np.intp)
        np.maximum.at(latest, owners, segment_of)
        keep = np.flatnonzero(segment_of == latest[owners])
        keep = keep[np.argsort(owners[keep], kind="stable")]
        del owners, segment_of
        merged = tuple(np.concatenate([seg[k] for seg in self._segments])[keep] for k in range(4))
        self._segments = [merged]  # type: ignore[list-item]
        self._stale = 0


@dataclass(frozen=True)
class PieceBoxes:
    """The pieces of a few surfaces, as :class:`PieceIndex` keeps them: (k, 4) float32 swept boxes, each piece's
    first and last row in its surface, and its surface's position among the few (all int32). Found where the
    surfaces are built, so the build process indexes them without opening the surfaces."""

    boxes: NDArray[np.float32]
    first: NDArray[np.int32]
    last: NDArray[np.int32]
    owner: NDArray[np.int32]


def piece_boxes(surfaces: Sequence[CCS]) -> PieceBoxes:
    """The pieces of ``surfaces`` and their swept boxes (one vectorised pass for them all)."""
    if not len(surfaces):
        empty = np.zeros(0, dtype=np.int32)
        return PieceBoxes(np.zeros((0, 4), np.float32), empty, empty, empty)
    sizes = np.array([len(s.base) for s in surfaces], dtype=np.intp)
    first, last, owner = piece_ranges(sizes, INDEX_PIECE_SEGMENTS)
    base = np.concatenate([s.base for s in surfaces])
    top = np.concatenate([s.top for s in surfaces])
    lo = _round(per_piece(np.minimum, np.minimum(base, top), first, last), -np.inf)
    hi = _round(per_piece(np.maximum, np.maximum(base, top), first, last), np.inf)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    return PieceBoxes(
        np.hstack([lo, hi]),
        (first - offsets[owner]).astype(np.int32),
        (last - offsets[owner]).astype(np.int32),
        owner.astype(np.int32),
    )


def _round(values: NDArray[np.float64], direction: float) -> NDArray[np.float32]:
    """float32 of ``values``, each rounded toward ``direction`` where float32 cannot hold it exactly."""
    out = values.astype(np.float32)
    wide = out.astype(np.float64)
    off = wide > values if direction < 0 else wide < values  # rounded the wrong way
    out[off] = np.nextafter(out[off], np.float32(direction))
    return out


@dataclass(frozen=True)
class Block:
    """One cell of the grid: the stretches of contour it checks.

    Attributes
    ----------
    near
        (m,) the contour of each stretch, sorted (a contour may have several).
    first, last
        (m,) the rows of each stretch, first to last (inclusive); -1, -1 for a whole contour.
    own
        (m,) True for the block's own stretches: runs of the pieces whose box centre lies in the cell, of the
        contours to check. The others are the runs of pieces whose boxes meet an own piece's box, checked
        against the own stretches only.
    """

    near: NDArray[np.intp]
    first: NDArray[np.intp]
    last: NDArray[np.intp]
    own: NDArray[np.bool_]


def surface_boxes(surfaces: Sequence[CCS]) -> NDArray[np.float64]:
    """(n, 4) box (minx, miny, maxx, maxy), metres, of each surface's base and top rows: every slice lies inside."""
    return np.array([s.bounds for s in surfaces], dtype=np.float64).reshape(-1, 4)


def spatial_blocks(
    boxes: NDArray[np.float64],
    pieces: PieceIndex,
    only: NDArray[np.intp] | None = None,
    per_block: int = BLOCK_CONTOURS,
) -> list[Block]:
    """The blocks of a grid over the owned contours' pieces, in row-major order; empty cells are left out.

    Each piece of an owned contour belongs to the cell that holds its box centre, so a contour longer than a
    cell is checked in pieces by the cells it crosses, and no block's work grows with the longest contour.

    Parameters
    ----------
    boxes
        (n, 4) contour boxes (:func:`surface_boxes`).
    pieces
        The pieces of the same n surfaces.
    only
        If given, a block owns only these contours' pieces (the ones to check); all contours still count as near.
    per_block
        Owned contours per block on average (the grid has about len(only) / per_block cells).
    """
    n = len(boxes)
    owned = np.arange(n, dtype=np.intp) if only is None else np.asarray(only, dtype=np.intp)
    if n == 0 or len(owned) == 0:
        return []
    # The grid spans the owned pieces only: a few rebuilt contours get small blocks of their own. Cells are
    # sized by rows too, so a block of long contours is no heavier for its worker than one of short ones.
    piece_boxes, first, last, owner, start = pieces.arrays()
    owned_pieces = concatenated_ranges(start[owned], start[owned + 1] - start[owned])
    rows = len(owned_pieces) * INDEX_PIECE_SEGMENTS
    side = max(1, math.ceil(math.sqrt(len(owned) / max(1, per_block))), math.ceil(math.sqrt(rows / BLOCK_ROWS)))
    centres = (piece_boxes[owned_pieces, :2].astype(np.float64) + piece_boxes[owned_pieces, 2:]) / 2
    lo = centres.min(axis=0)
    span = np.maximum(centres.max(axis=0) - lo, 1e-9)
    cell = np.minimum((((centres - lo) / span) * side).astype(np.intp), side - 1)
    key = cell[:, 1] * side + cell[:, 0]
    del centres, cell
    order = np.argsort(key, kind="stable")
    buckets = _Buckets(piece_boxes)
    blocks = []
    for group in np.split(owned_pieces[order], np.flatnonzero(np.diff(key[order])) + 1):
        own = np.sort(group)
        # Only the pieces filed near this block are compared with its own (on the arrays: a geometry per box
        # had cost more than the comparisons).
        candidates = buckets.near(piece_boxes[own])
        met = boxes_meeting(piece_boxes[own], piece_boxes[candidates])
        blocks.append(_block(own, candidates[met], first, last, owner, start))
    return blocks


#: Pieces per bucket of the grid that narrows a block's search to the pieces around it.
PIECES_PER_BUCKET = 256
#: Boxes filed at a time.
FILE_CHUNK = 1 << 16


class _Buckets:
    """Pieces filed by the cells of a square grid their boxes overlap (a piece across a cell edge is in both)."""

    def __init__(self, boxes: NDArray[np.floating]) -> None:
        self.side = max(1, math.ceil(math.sqrt(len(boxes) / PIECES_PER_BUCKET)))
        self.lo = boxes[:, :2].min(axis=0) if len(boxes) else np.zeros(2)
        extent = (boxes[:, 2:].max(axis=0) - self.lo) if len(boxes) else np.ones(2)
        self.cell = np.maximum(extent / self.side, 1e-9)
        # Filed a chunk of boxes at a time: the temporaries of filing a million boxes at once were 100+ MB.
        filed = [self._cells_of(boxes[k : k + FILE_CHUNK], k) for k in range(0, len(boxes), FILE_CHUNK)]
        cells = np.concatenate([c for c, _ in filed]) if filed else np.zeros(0, dtype=np.int32)
        piece = np.concatenate([p for _, p in filed]) if filed else np.zeros(0, dtype=np.int32)
        del filed
        order = np.argsort(cells, kind="stable")
        self.pieces = piece[order]
        self.start = np.searchsorted(cells[order], np.arange(self.side * self.side + 1)).astype(np.intp)

    def _cells_of(self, boxes: NDArray[np.floating], first: int = 0) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
        """Every (cell, box index) pair of a cell a box overlaps (box indices counted from ``first``)."""
        c0 = np.clip(np.floor((boxes[:, :2] - self.lo) / self.cell), 0, self.side - 1).astype(np.intp)
        c1 = np.clip(np.floor((boxes[:, 2:] - self.lo) / self.cell), 0, self.side - 1).astype(np.intp)
        nx, ny = c1[:, 0] - c0[:, 0] + 1, c1[:, 1] - c0[:, 1] + 1
        counts = nx * ny
        which = np.repeat(np.arange(len(boxes), dtype=np.intp), counts)
        k = concatenated_ranges(np.zeros(len(boxes), dtype=np.intp), counts)
        ix = c0[which, 0] + k % nx[which]
        iy = c0[which, 1] + k // nx[which]
        return (iy * self.side + ix).astype(np.int32), (which + first).astype(np.int32)

    def near(self, boxes: NDArray[np.floating]) -> NDArray[np.intp]:
        """Sorted indices of the pieces filed in any cell that one of ``boxes`` overlaps."""
        cells = np.unique(self._cells_of(boxes)[0])
        return np.unique(
            self.pieces[concatenated_ranges(self.start[cells], self.start[cells + 1] - self.start[cells])]
        )


def _block(
    own: NDArray[np.intp],
    hit: NDArray[np.intp],
    first: NDArray[np.integer],
    last: NDArray[np.integer],
    owner: NDArray[np.integer],
    start: NDArray[np.intp],
) -> Block:
    """A block from its own pieces and the pieces that meet them: the runs of consecutive own pieces are its
    own stretches, the runs of the other pieces met its near ones (a long contour that winds in and out of
    the block's reach is checked only where it comes near)."""
    others = np.setdiff1d(np.unique(hit), own, assume_unique=True)
    runs = [_runs(own, owner), _runs(others, owner)]
    begin = np.concatenate([r[0] for r in runs])
    end = np.concatenate([r[1] for r in runs])
    contour = owner[begin].astype(np.intp)
    whole = (begin == start[contour]) & (end == start[contour + 1] - 1)
    order = np.argsort(contour, kind="stable")
    return Block(
        near=contour[order],
        first=np.where(whole, -1, first[begin]).astype(np.intp)[order],
        last=np.where(whole, -1, last[end]).astype(np.intp)[order],
        own=np.repeat([True, False], [len(runs[0][0]), len(runs[1][0])])[order],
    )


def _runs(pieces: NDArray[np.intp], owner: NDArray[np.integer]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """First and last piece of each run of consecutive pieces of one contour among sorted ``pieces``."""
    if not len(pieces):
        return pieces, pieces
    breaks = np.flatnonzero((np.diff(pieces) != 1) | (np.diff(owner[pieces]) != 0)) + 1
    return pieces[np.concatenate([[0], breaks])], pieces[np.concatenate([breaks, [len(pieces)]]) - 1]


class NearSlice(NamedTuple):
    """Rows ``first`` .. ``last`` of the surface that lies at ``whole`` in the spool's file: a near stretch for
    a worker that reads the spool itself to cut (:func:`_block_tasks`)."""

    whole: FileSlice
    first: int
    last: int


#: What a block's task gets for each of its surfaces (:func:`_block_tasks`).
NearItem = SurfaceRows | bytes | FileSlice | NearSlice


class BlockContacts(NamedTuple):
    """What a block's task finds: the pairs (i, j), i < j, of local indices whose slices meet, and for those of
    them whose two whole surfaces the task had, whether their input lines already touch (the input's touch test,
    :class:`~engine.ccsm.topology.InputTouches`, on their base rows)."""

    pairs: set[tuple[int, int]]
    touching: dict[tuple[int, int], bool]


def block_contacts(
    near: Sequence[NearItem], own: Sequence[int], ladder: NDArray[np.float64], steps: Sequence[int]
) -> BlockContacts:
    """Pairs (i, j), i < j, of local indices (into ``near``) whose slices meet at some checked step, each with
    an ``own`` surface in it. The surfaces come as :func:`_block_tasks` sends them: the block's own as the
    spool keeps them, or where they lie in its file (read and opened here, in the worker), the others cut to
    their near stretches, or where their whole surface lies with the rows to cut here.

    Where both surfaces of a pair came whole (or where they lie), their input lines' touch test is made here too,
    so the build process need not read them for it.

    Raises
    ------
    FileUnreachable
        This worker cannot read the spool's file: the task goes again with its surfaces.
    """
    surfaces, wholes = _near_and_whole(near)
    pairs = new_contact_pairs(surfaces, ladder, steps, set(own))
    asked = sorted((a, b) for a, b in pairs if wholes[a] is not None and wholes[b] is not None)
    touching = pairs_touching(asked, lambda numbers: [cast("CCS", wholes[k]).base for k in numbers])
    release_free_memory()  # a worker's next block starts from what this one freed
    return BlockContacts(pairs, touching)


def near_surfaces(near: Sequence[NearItem]) -> list[SurfaceRows]:
    """A block task's surfaces as the contact check reads them: read where they lie in the spool's file (each
    file opened once), opened, and the near ones cut to their stretches. The surfaces a worker opens from the
    file are kept for its next blocks (:data:`OPENED_NEAR`)."""
    return _near_and_whole(near)[0]


def _near_and_whole(near: Sequence[NearItem]) -> tuple[list[SurfaceRows], list[CCS | None]]:
    """:func:`near_surfaces`, and each item's whole surface where the task gave it whole or where it lies
    (None for a stretch cut in the build process)."""
    wanted = [item.whole if isinstance(item, NearSlice) else item for item in near]
    opened_items = OPENED_NEAR.opened(wanted)
    surfaces = [
        _stretch(cast("CCS", surface), item.first, item.last) if isinstance(item, NearSlice) else surface
        for item, surface in zip(near, opened_items, strict=True)
    ]
    wholes = [None if isinstance(surface, NearStretch) else cast("CCS", surface) for surface in opened_items]
    return surfaces, wholes


#: Bytes of surfaces a worker keeps opened from the spool's file between its block tasks.
OPENED_NEAR_BYTES = 64 << 20


class OpenedSlices:
    """Surfaces opened from the spool's file, by where they lie, the most recently used kept up to
    :data:`OPENED_NEAR_BYTES`: neighbouring blocks share most of their near surfaces, and a long contour
    passing by is near many blocks, so a worker would otherwise read and unpickle it for each (the build
    process kept such a cache, :class:`NearCache`, when it read them). A slice names bytes written once and
    never moved, so what it names never changes: an entry needs no forgetting."""

    def __init__(self) -> None:
        self.items: OrderedDict[FileSlice, CCS] = OrderedDict()
        self.size = 0
        self._lock = threading.Lock()  # a Dask worker may run tasks in several threads

    def opened(self, items: Sequence[Any]) -> list[Any]:
        """``items`` opened: each :class:`FileSlice` read (the ones not kept, in one pass) and unpickled, and
        kept; anything else opened as it is (:func:`~engine.payloads.opened`)."""
        with self._lock:
            return self._opened(items)

    def _opened(self, items: Sequence[Any]) -> list[Any]:
        missing = list(dict.fromkeys(i for i in items if isinstance(i, FileSlice) and i not in self.items))
        for where, blob in zip(missing, fetched(missing), strict=True):
            self.items[where] = surface_of(cast(bytes, blob))
            self.size += where.length
        out = []
        for item in items:
            if isinstance(item, FileSlice):
                self.items.move_to_end(item)
                out.append(self.items[item])
            else:
                out.append(opened(item))
        wanted = len({i for i in items if isinstance(i, FileSlice)})
        while self.size > OPENED_NEAR_BYTES and len(self.items) > wanted:  # never the ones just asked for
            where, _ = self.items.popitem(last=False)
            self.size -= where.length
        return out


#: The surfaces this worker process has opened from spool files.
OPENED_NEAR = OpenedSlices()


def input_touches(spool: Spool) -> InputTouches:
    """The input's touching pairs of a spool's surfaces (their base rows), asked pair by pair."""
    return InputTouches(_SpoolBases(spool))  # type: ignore[arg-type]


class _SpoolBases:
    """The base rows of a spool's surfaces, read when asked: the input lines for :class:`InputTouches`."""

    def __init__(self, spool: Spool) -> None:
        self.spool = spool

    def __getitem__(self, index: int) -> Coords:
        return self.spool.get([index])[0].base

    def take(self, indices: Sequence[int]) -> list[Coords]:
        """The base rows of several surfaces, read together."""
        return [s.base for s in self.spool.get(indices)]


def _block_tasks(
    blocks: Sequence[Block],
    spool: Spool,
    ladder: NDArray[np.float64],
    steps: list[int],
    cache: NearCache | None = None,
    *,
    sliced: bool = False,
) -> Iterator[tuple[Any, ...]]:
    """One task per block, each block's surfaces read from the spool only when its task is sent: its own
    surfaces as the spool keeps them, every other one cut to its near stretch here, so that a long contour
    passing by is not shipped whole to every block it passes (a task's size follows the block's rows). The
    surfaces are read through ``cache`` (None: a new one).

    ``sliced`` (the tasks go to workers): where the spool can say where its surfaces lie in its file
    (:meth:`Spool.get_slices`), a task carries only that, and the worker reads and cuts them itself, so this
    process reads, opens and sends none of their bytes."""
    cache = cache if cache is not None else NearCache(spool)
    for b in blocks:
        slices = spool.get_slices(b.near.tolist()) if sliced else None
        if slices is not None:
            near_slices: list[NearItem] = [
                whole if f < 0 else NearSlice(whole, f, la)
                for whole, f, la in zip(slices, b.first.tolist(), b.last.tolist(), strict=True)
            ]
            yield near_slices, np.flatnonzero(b.own).tolist(), ladder, steps
            continue
        near: list[CCS | bytes | NearStretch] = []
        # A few surfaces read at a time: whole, the long contours passing by a block can weigh far more than
        # their stretches, and the block's task holds only those.
        for k in range(0, len(b.near), NEAR_READ_BATCH):
            at = slice(k, k + NEAR_READ_BATCH)
            numbers = b.near[at].tolist()
            payloads = cache.payloads(numbers)
            near.extend(
                p if f < 0 else _stretch(cache.surface(n), f, la)
                for n, p, f, la in zip(numbers, payloads, b.first[at].tolist(), b.last[at].tolist(), strict=True)
            )
        yield near, np.flatnonzero(b.own).tolist(), ladder, steps


#: Bytes of surfaces :class:`NearCache` keeps while block tasks are made.
NEAR_CACHE_BYTES = 32 << 20


class NearCache:
    """The surfaces read for the blocks' tasks, the most recently used kept up to ``budget`` bytes (as the spool
    keeps them, and opened once a stretch of them is cut; None: :data:`NEAR_CACHE_BYTES`): neighbouring blocks
    share most of their near contours, and on dense data reading and opening them again for every block cost
    more than the checks. Kept across the repair's checks, each re-check reads again only what was rebuilt
    (:meth:`forget`) or evicted: a new cache per check had read most surfaces of a round's blocks again.
    """

    def __init__(self, spool: Spool, budget: int | None = None) -> None:
        self.spool = spool
        self.budget = NEAR_CACHE_BYTES if budget is None else budget
        self.items: OrderedDict[int, list[Any]] = OrderedDict()  # number -> [payload, opened surface or None]
        self.size = 0

    def payloads(self, numbers: list[int]) -> list[CCS | bytes]:
        """The surfaces ``numbers`` as the spool keeps them (read only those not kept)."""
        # Each number looked up on its own: ``set - dict.keys()`` walks every key kept (thousands on dense data),
        # which had cost more than the reads it saved.
        missing = sorted({n for n in numbers if n not in self.items})
        for n, payload in zip(missing, self.spool.get_payloads(missing), strict=True) if missing else ():
            self.items[n] = [payload, None]
            self.size += _payload_bytes(payload)
        for n in numbers:
            self.items.move_to_end(n)
        while self.size > self.budget and len(self.items) > len(numbers):  # never the ones just asked for
            _, entry = self.items.popitem(last=False)
            self.size -= _entry_bytes(entry)
        return [self.items[n][0] for n in numbers]

    def forget(self, numbers: Iterable[int]) -> None:
        """Drop surfaces ``numbers`` (replaced in the spool since they were read)."""
        for n in numbers:
            entry = self.items.pop(n, None)
            if entry is not None:
                self.size -= _entry_bytes(entry)

    def surface(self, number: int) -> CCS:
        """Surface ``number`` opened (it must have been asked for by :meth:`payloads` just before)."""
        entry = self.items[number]
        if entry[1] is None:
            loaded = surface_of(entry[0])
            entry[1] = loaded
            if loaded is not entry[0]:
                self.size += _payload_bytes(loaded)
        surface: CCS = entry[1]
        return surface


def _payload_bytes(payload: CCS | bytes) -> int:
    return len(payload) if isinstance(payload, bytes) else payload.base.nbytes + payload.top.nbytes


def _entry_bytes(entry: list[Any]) -> int:
    """What a :class:`NearCache` entry [payload, opened surface or None] counts for (a surface that is its own
    payload, as a memory spool keeps it, only once)."""
    payload, opened = entry
    return _payload_bytes(payload) + (0 if opened is None or opened is payload else _payload_bytes(opened))


#: Surfaces of a block read from the spool at a time while its task is made.
NEAR_READ_BATCH = 8

#: Bytes of block tasks in flight (sent and not yet answered) before the next block is read: with the
#: look-ahead's count alone, a run of blocks of long contours held hundreds of MB in the build process.
BLOCK_TASK_BUDGET_BYTES = 48 << 20


def _task_bytes(task: tuple[Any, ...]) -> int:
    """About the bytes this process holds of a block task's surfaces: their payloads as the spool keeps them,
    or their rows (none for the slices of a file the worker reads itself)."""
    return sum(
        len(p) if isinstance(p, bytes) else 0 if isinstance(p, (FileSlice, NearSlice)) else p.base.nbytes + p.top.nbytes
        for p in task[0]
    )


def _with_surfaces(spool: Spool) -> Callable[[tuple[Any, ...]], tuple[Any, ...]]:
    """How a block's task is sent again when its worker cannot read the spool's file: with its surfaces read
    and cut here (as the spool's file is this process's own), and no task sliced from then on."""

    def again(task: tuple[Any, ...]) -> tuple[Any, ...]:
        spool.stop_slices()
        return (near_surfaces(task[0]), *task[1:])

    return again


class NearStretch(NamedTuple):
    """Rows ``first`` .. ``last`` of a surface passing near a block, with what the contact check reads besides
    (``topology.SurfaceRows``): all a block's task carries of a contour it only checks its own against. A whole
    CCS cut with ``dataclasses.replace`` had cost the build process 20 µs a stretch (every field checked
    again), and its similarity tables went into every task."""

    base: Coords
    top: Coords
    t_at_scale: NDArray[np.float64]
    vanish_scale: float


def _stretch(surface: CCS, first: int, last: int) -> NearStretch:
    """Rows ``first`` .. ``last`` of a surface (its slices there), as the blocks' check takes them."""
    rows = slice(first, last + 1)
    return NearStretch(surface.base[rows].copy(), surface.top[rows].copy(), surface.t_at_scale, surface.vanish_scale)


def find_crossings_by_block(
    spool: Spool,
    boxes: NDArray[np.float64],
    pieces: PieceIndex,
    ladder: NDArray[np.float64],
    steps: Sequence[int],
    only: set[int] | None = None,
    executor: Executor | None = None,
    per_block: int | None = None,
    touches: InputTouches | None = None,
    cache: NearCache | None = None,
) -> set[int]:
    """Indices of the surfaces in a new contact (with one of ``only``, if given), found block by block:
    the same answer as :func:`~engine.ccsm.topology.find_new_crossings` over the whole set with the input's
    touches allowed, with an index per block instead of one over everything.

    Parameters
    ----------
    spool
        The surfaces, numbered 0 .. n - 1; only one block's (times the executor's look-ahead) are read at once.
    boxes
        (n, 4) their boxes (:func:`surface_boxes`).
    pieces
        Their pieces.
    ladder, steps
        As for :func:`~engine.ccsm.topology.find_new_crossings`.
    only
        Restrict the search to contacts that involve these surfaces (the ones just rebuilt).
    executor
        Where the blocks are checked (a local pool or a Dask cluster); None = this process.
    per_block
        Owned contours per block on average; None = :data:`BLOCK_CONTOURS`, or :data:`REBUILT_PER_BLOCK`
        with ``only``.
    touches
        The input's touching pairs, asked pair by pair (kept across calls so each pair is asked once); None =
        a new one on the spool's base rows.
    cache
        The surfaces read for earlier checks (kept across calls; the caller forgets the ones it replaces in the
        spool); None = a new one.
    """
    checked = None if only is None else np.array(sorted(only), dtype=np.intp)
    if per_block is None:
        per_block = BLOCK_CONTOURS if only is None else REBUILT_PER_BLOCK
    blocks = spatial_blocks(boxes, pieces, checked, per_block)
    touches = touches if touches is not None else input_touches(spool)
    found: set[int] = set()
    tasks = _block_tasks(blocks, spool, ladder, list(steps), cache, sliced=executor is not None)
    checks = map_ordered(
        executor,
        block_contacts,
        tasks,
        weight=_task_bytes,
        budget=BLOCK_TASK_BUDGET_BYTES,
        refetch=_with_surfaces(spool),
    )
    for block, (pairs, touching) in zip(blocks, checks, strict=True):
        # Two stretches of one contour meet where they join (the input touch test would say so too).
        met = {(int(block.near[a]), int(block.near[b])) for a, b in pairs} - {(i, i) for i in block.near.tolist()}
        # The worker's answers first (a pair's first answer is kept), then the rest asked together here: each
        # input line read once.
        touches.record({(int(block.near[a]), int(block.near[b])): hit for (a, b), hit in touching.items()})
        touches.learn(met)
        for pair in met:
            if pair not in touches:
                found.update(pair)
    release_free_memory()
    return found
