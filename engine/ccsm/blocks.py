"""Spatial blocks for the crossing repair: each block's contours are checked against the contours that can reach
them, not against the whole set (docs/design.md section 4.8, issue 12 item 2).

A contour belongs to the block of a square grid over the set that holds its box centre; its box is the box of
its base and top rows, which holds every slice at every t. A block's *near* contours are its own and every
contour whose box overlaps one of theirs: the only contours whose slices can meet its own. Checking each block's
own contours against its near ones therefore finds exactly the meeting pairs a check of the whole set finds
(each pair at least once, from the block of either contour), so the repair's decisions do not change. Each
block's check needs only its near contours' rows: blocks are checked apart from each other, on any executor.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from numpy.typing import NDArray

from engine.ccsm.spool import Spool
from engine.ccsm.topology import InputTouches, new_contact_pairs
from engine.parallel import map_ordered
from engine.types import Coords

if TYPE_CHECKING:
    from engine.ccsm.ccs import CCS

#: Contours per block on average. A long contour's box overlaps many blocks, so every block it reaches indexes
#: it again: on the sample 9 blocks cost 7.9 s of CPU in the first check against 7.3 s for 2 (and 6.8 s for the
#: whole-set check before the blocks); few, large blocks until that is fixed.
BLOCK_CONTOURS = 1024


@dataclass(frozen=True)
class Block:
    """One cell of the grid.

    Attributes
    ----------
    own
        (k,) indices of the contours whose box centre lies in the cell.
    near
        (m,) sorted indices of ``own`` and of every contour whose box overlaps the box of one of them.
    """

    own: NDArray[np.intp]
    near: NDArray[np.intp]


def surface_boxes(surfaces: Sequence[CCS]) -> NDArray[np.float64]:
    """(n, 4) box (minx, miny, maxx, maxy), metres, of each surface's base and top rows: every slice lies inside."""
    out = np.empty((len(surfaces), 4))
    for i, s in enumerate(surfaces):
        both = np.concatenate([s.base, s.top])
        out[i, :2] = both.min(axis=0)
        out[i, 2:] = both.max(axis=0)
    return out


def spatial_blocks(
    boxes: NDArray[np.float64], only: NDArray[np.intp] | None = None, per_block: int = BLOCK_CONTOURS
) -> list[Block]:
    """The blocks of a grid over the boxes' centres, in row-major order; empty cells are left out.

    Parameters
    ----------
    boxes
        (n, 4) contour boxes (:func:`surface_boxes`).
    only
        If given, a block owns only these contours (the ones to check); all contours still count as near.
    per_block
        Contours per block on average (the grid has about n / per_block cells).

    >>> boxes = np.array([[0, 0, 1, 1], [0.5, 0.5, 2, 2], [9, 9, 10, 10]], dtype=float)
    >>> [(b.own.tolist(), b.near.tolist()) for b in spatial_blocks(boxes, per_block=1)]
    [([0, 1], [0, 1]), ([2], [2])]
    """
    n = len(boxes)
    owned = np.arange(n, dtype=np.intp) if only is None else np.asarray(only, dtype=np.intp)
    if n == 0 or len(owned) == 0:
        return []
    side = max(1, math.ceil(math.sqrt(n / max(1, per_block))))
    centres = (boxes[:, :2] + boxes[:, 2:]) / 2
    lo = centres.min(axis=0)
    span = np.maximum(centres.max(axis=0) - lo, 1e-9)
    cell = np.minimum((((centres[owned] - lo) / span) * side).astype(np.intp), side - 1)
    key = cell[:, 1] * side + cell[:, 0]
    order = np.argsort(key, kind="stable")
    tree = shapely.STRtree(shapely.box(boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]))
    blocks = []
    for group in np.split(owned[order], np.flatnonzero(np.diff(key[order])) + 1):
        own = np.sort(group)
        _, hits = tree.query(shapely.box(*boxes[own].T))
        blocks.append(Block(own=own, near=np.union1d(own, hits).astype(np.intp)))
    return blocks


def cut_to_region(surface: CCS, region: NDArray[np.float64]) -> CCS | None:
    """The stretch of ``surface`` whose segments can reach ``region`` (minx, miny, maxx, maxy), or None.

    A segment's slices at every t lie in the box of its ends' rows at t = 0 and t = 1, so a segment whose box
    misses the region can meet nothing inside it. The rows from the first to the last segment that reaches the
    region are kept (one stretch, so the vertices' motion is unchanged): a contour that runs through many
    blocks is then checked in each for about its length there, not for its whole length.
    """
    rows = np.concatenate([surface.base[:, None], surface.top[:, None]], axis=1)  # (M, 2 rows, 2)
    lo, hi = rows.min(axis=1), rows.max(axis=1)
    seg_lo, seg_hi = np.minimum(lo[:-1], lo[1:]), np.maximum(hi[:-1], hi[1:])
    reach = np.flatnonzero(np.all((seg_lo <= region[2:]) & (seg_hi >= region[:2]), axis=1))
    if not len(reach):
        return None
    first, last = int(reach[0]), int(reach[-1]) + 2
    if first == 0 and last == len(rows):
        return surface
    return replace(surface, base=surface.base[first:last], top=surface.top[first:last])


def block_contacts(
    near: Sequence[CCS | None], own: Sequence[int], ladder: NDArray[np.float64], steps: Sequence[int]
) -> set[tuple[int, int]]:
    """Pairs (i, j), i < j, of local indices (into ``near``) whose slices meet at some checked step, each with
    an ``own`` surface in it; None stands for a surface that cannot reach the block (so it meets nothing)."""
    kept = [i for i, s in enumerate(near) if s is not None]
    position = {i: k for k, i in enumerate(kept)}
    found = new_contact_pairs([near[i] for i in kept], ladder, steps, {position[i] for i in own})  # type: ignore[misc]
    return {(kept[a], kept[b]) for a, b in found}


def input_touches(spool: Spool) -> InputTouches:
    """The input's touching pairs of a spool's surfaces (their base rows), asked pair by pair."""
    return InputTouches(_SpoolBases(spool))  # type: ignore[arg-type]


class _SpoolBases:
    """The base rows of a spool's surfaces, read when asked: the input lines for :class:`InputTouches`."""

    def __init__(self, spool: Spool) -> None:
        self.spool = spool

    def __getitem__(self, index: int) -> Coords:
        return self.spool.get([index])[0].base


def _block_tasks(
    blocks: Sequence[Block], spool: Spool, boxes: NDArray[np.float64], ladder: NDArray[np.float64], steps: list[int]
) -> Iterator[tuple[Any, ...]]:
    """One task per block, each block's surfaces read from the spool only when its task is sent."""
    for b in blocks:
        region = np.concatenate([boxes[b.own, :2].min(axis=0), boxes[b.own, 2:].max(axis=0)])
        own = set(b.own.tolist())
        indices = b.near.tolist()
        near = [s if i in own else cut_to_region(s, region) for i, s in zip(indices, spool.get(indices), strict=True)]
        yield near, np.searchsorted(b.near, b.own).tolist(), ladder, steps


def find_crossings_by_block(
    spool: Spool,
    boxes: NDArray[np.float64],
    ladder: NDArray[np.float64],
    steps: Sequence[int],
    only: set[int] | None = None,
    executor: Executor | None = None,
    per_block: int | None = None,
    touches: InputTouches | None = None,
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
    ladder, steps
        As for :func:`~engine.ccsm.topology.find_new_crossings`.
    only
        Restrict the search to contacts that involve these surfaces (the ones just rebuilt).
    executor
        Where the blocks are checked (a local pool or a Dask cluster); None = this process.
    per_block
        Contours per block on average; None = :data:`BLOCK_CONTOURS`.
    touches
        The input's touching pairs, asked pair by pair (kept across calls so each pair is asked once); None =
        a new one on the spool's base rows.
    """
    checked = None if only is None else np.array(sorted(only), dtype=np.intp)
    blocks = spatial_blocks(boxes, checked, BLOCK_CONTOURS if per_block is None else per_block)
    touches = touches if touches is not None else input_touches(spool)
    found: set[int] = set()
    tasks = _block_tasks(blocks, spool, boxes, ladder, list(steps))
    for block, pairs in zip(blocks, map_ordered(executor, block_contacts, tasks), strict=True):
        for a, b in pairs:
            pair = (int(block.near[a]), int(block.near[b]))
            if pair not in touches:
                found.update(pair)
    return found
