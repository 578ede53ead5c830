"""Build the CCS of every contour of a set, on all cores, with progress reports.

All per-contour work happens here, once: a tile request later only interpolates two stored rows.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from engine.ccsm.blocks import (
    NearCache,
    PieceBoxes,
    PieceIndex,
    find_crossings_by_block,
    input_touches,
    piece_boxes,
    surface_boxes,
)
from engine.ccsm.ccs import CCS, slice_area
from engine.ccsm.contour_issues import build_or_keep_input, nothing_to_serve
from engine.ccsm.regression import ScaleModel, fit_scale_model
from engine.ccsm.spool import MemorySpool, Spool
from engine.ccsm.survey import survey_contours
from engine.geom.kernels import first_small_slice
from engine.geom.polyline import ring_areas
from engine.heap import keep_big_buffers_out_of_the_heap, release_free_memory
from engine.parallel import local_pool, map_ordered
from engine.params import BuildParams
from engine.payloads import FileSlice, opened, pickled
from engine.tolerances import MIN_VISIBLE_RING_SIDE_M
from engine.types import BadFeature, Contour, ContourSet, ContourSubset, contour_payloads

#: Called with (contours done, contours in total) as the build goes.
ProgressCallback = Callable[[int, int], None]

#: Contours per task sent to a worker process: large enough that pickling is a small share of the work.
CHUNK = 64


@dataclass
class BuiltSet:
    """The CCS of every usable contour of a set, and how scales map to t.

    Attributes
    ----------
    surfaces
        One CCS per usable contour, in input order.
    model
        The scale model (ladder of scales, regression per group).
    params
        The parameters of the build.
    working_crs, source_crs
        CRS of the surfaces' coordinates (metres) and of the input.
    bad_features
        Input features left out by the reader or the build, each with its reason.
    repaired
        Contours rebuilt with a finer target so that their slices cross no other contour.
    inputs
        The input contour of each surface, in the same order (what the store keeps as the original).
    """

    surfaces: list[CCS]
    model: ScaleModel
    params: BuildParams
    working_crs: str
    source_crs: str
    bad_features: list[BadFeature] = field(default_factory=list)
    name: str = "contours"
    interval: float | None = None
    repaired: int = 0
    inputs: Sequence[Contour] = ()

    @property
    def count(self) -> int:
        """How many surfaces (as :attr:`SpooledSet.count`)."""
        return len(self.surfaces)

    def payloads_in_batches(self, size: int, *, sliced: bool = False) -> Iterator[tuple[list[CCS], list[Contour]]]:
        """The surfaces in input order with their input contours, ``size`` at a time (as
        :meth:`SpooledSet.payloads_in_batches`; a surface in memory is its own payload, never sliced)."""
        for i in range(0, len(self.surfaces), size):
            yield self.surfaces[i : i + size], list(self.inputs[i : i + size])

    def stop_slices(self) -> None:
        """As :meth:`SpooledSet.stop_slices` (a set in memory gives no slices)."""


def vanish_scale(ccs: CCS, model: ScaleModel) -> float:
    """Smallest scale denominator at which a ring is too small to show (docs/design.md section 4); inf for lines.

    Below the source scale the ring is L0 and above the target scale it is Ln, so there the answer follows
    from their areas; in between, the ring's slice at each ladder scale is checked.
    """
    if not ccs.closed:
        return math.inf
    area0 = slice_area(ccs, 0.0)
    first = math.sqrt(area0) / MIN_VISIBLE_RING_SIDE_M
    if first <= model.source_scale:
        return first
    t = np.clip(np.asarray(ccs.t_at_scale, dtype=np.float64), 0.0, 1.0)
    smallest = (MIN_VISIBLE_RING_SIDE_M * np.asarray(model.ladder, dtype=np.float64)) ** 2
    # One compiled pass up to the first small slice; NumPy's areas only where that pass cannot tell (an area
    # within rounding of its threshold). Making every ladder slice at once had been a twentieth of a build.
    first_small = first_small_slice(ccs.base[:-1], ccs.top[:-1], t, smallest)
    if first_small == -2:
        tt = t[:, None, None]
        small = np.flatnonzero(ring_areas((1.0 - tt) * ccs.base[:-1] + tt * ccs.top[:-1]) < smallest)
        first_small = int(small[0]) if len(small) else -1
    if first_small >= 0:
        return float(model.ladder[first_small])
    return max(model.target_scale, math.sqrt(slice_area(ccs, 1.0)) / MIN_VISIBLE_RING_SIDE_M)


def _build_chunk(
    contours: Sequence[Contour | bytes],
    labels: Sequence[int],
    params: BuildParams,
    model: ScaleModel,
    factors: Sequence[float] | None = None,
) -> list[CCS | BadFeature]:
    """The surface of each contour (as the reader keeps it: opened here, on the worker) at its factor."""
    out: list[CCS | BadFeature] = []
    factors = factors if factors is not None else [1.0] * len(contours)
    for contour, group, factor in zip(contours, labels, factors, strict=True):
        out.append(build_or_keep_input(opened(contour), int(group), params, model, factor))
    return out


@dataclass(frozen=True)
class KeptChunk:
    """A chunk's surfaces as the spool keeps them, and what the build process needs of them without opening
    them: their boxes and their pieces' boxes (for the crossing repair's blocks).

    Attributes
    ----------
    built
        Position in the chunk of each surface (the others are in ``failed``).
    payloads
        The surfaces, pickled for a spool that keeps pickles, else as they are.
    failed
        The chunk's contours that could not carry a surface.
    bounds
        (k, 4) box of each surface (:func:`~engine.ccsm.blocks.surface_boxes`).
    pieces
        Their pieces (:func:`~engine.ccsm.blocks.piece_boxes`).
    factors
        The tolerance factor each surface was built with (``CCS.tolerance_factor``).
    """

    built: list[int]
    payloads: Sequence[CCS | bytes]
    failed: list[BadFeature]
    bounds: NDArray[np.float64]
    pieces: PieceBoxes
    factors: list[float]


def _build_kept_chunk(
    contours: Sequence[Contour | bytes],
    labels: Sequence[int],
    params: BuildParams,
    model: ScaleModel,
    pickle_surfaces: bool,
    factors: Sequence[float] | None = None,
) -> KeptChunk:
    """A chunk built (at ``factors``, the repair's rebuilds; else the first build), as a worker sends it back
    (:class:`KeptChunk`): the contours come as the reader keeps them and are opened here, the surfaces go back
    as the spool keeps them with their boxes and pieces, so the build process neither opens nor pickles either,
    nor measures them (``engine.payloads``)."""
    results = _build_chunk(contours, labels, params, model, factors)
    surfaces = [r for r in results if isinstance(r, CCS)]
    return KeptChunk(
        built=[k for k, r in enumerate(results) if isinstance(r, CCS)],
        payloads=[pickled(s) for s in surfaces] if pickle_surfaces else surfaces,
        failed=[r for r in results if isinstance(r, BadFeature)],
        bounds=surface_boxes(surfaces),
        pieces=piece_boxes(surfaces),
        factors=[s.tolerance_factor for s in surfaces],
    )


def _pool(executor: Executor | None, workers: int, chunks: int | None) -> AbstractContextManager[Executor | None]:
    """Where a build's tasks run: the given executor, a local pool of ``workers``, or this process (None) when
    there is one worker or at most one chunk of work (``chunks`` None: not known yet)."""
    if executor is not None:
        return nullcontext(executor)
    if workers == 1 or (chunks is not None and chunks <= 1):
        return nullcontext(None)
    return local_pool(workers)


def build_pool(
    executor: Executor | None, workers: int | None, contours: int | None
) -> AbstractContextManager[Executor | None]:
    """The executor for the whole of a build of ``contours`` contours and its save: the given one, else a local
    pool of ``workers`` processes (None: one per core) when there is more than one chunk of work, else None
    (this process). Opened once by the caller, so that the store rows and label candidates of the save run on
    the same processes as the build, not serially in the process that writes the store. ``contours`` None: a
    source not read yet (a DEM, traced on the pool), which gets a pool whenever there are several workers."""
    workers = default_workers() if workers is None else max(1, workers)
    return _pool(executor, workers, None if contours is None else -(-contours // CHUNK))


def default_workers() -> int:
    """Worker processes: one per core the process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


@dataclass
class SpooledSet:
    """A built set whose surfaces are in a spool (:mod:`engine.ccsm.spool`), numbered 0 .. ``count`` - 1 in
    input order: what :func:`build_into` returns, to be written batch by batch. ``inputs`` are their input
    contours, read when asked (from the reader's scratch file for a big source). The other attributes are
    those of :class:`BuiltSet`."""

    spool: Spool
    inputs: Sequence[Contour]
    count: int
    model: ScaleModel
    params: BuildParams
    working_crs: str
    source_crs: str
    bad_features: list[BadFeature]
    name: str
    interval: float | None
    repaired: int

    def payloads_in_batches(
        self, size: int, *, sliced: bool = False
    ) -> Iterator[tuple[Sequence[CCS | bytes | FileSlice], list[Contour | bytes]]]:
        """The surfaces in input order as the spool keeps them (:meth:`Spool.get_payloads`, sent to a worker
        without this process opening them) with their input contours, ``size`` at a time (only one batch of
        each is read into memory). ``sliced``: where the spool can, only where the surfaces lie in its file
        (:meth:`Spool.get_slices`), for a worker to read them itself."""
        for start in range(0, self.count, size):
            stop = min(self.count, start + size)
            slices = self.spool.get_slices(range(start, stop)) if sliced else None
            surfaces = self.spool.get_payloads(range(start, stop)) if slices is None else slices
            yield surfaces, contour_payloads(self.inputs, range(start, stop))

    def stop_slices(self) -> None:
        """Send the surfaces themselves from now on: a worker could not read the spool's file."""
        self.spool.stop_slices()


def build_contour_set(
    contour_set: ContourSet,
    params: BuildParams | None = None,
    *,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
    executor: Executor | None = None,
) -> BuiltSet:
    """Build the CCS of every contour of ``contour_set``, in memory (:func:`build_into` with a memory spool).

    Parameters and the build are those of :func:`build_into`.

    Returns
    -------
    BuiltSet
        Contours that could not be built are listed in ``bad_features`` with the reason; the rest are built.
    """
    spooled = build_into(MemorySpool(), contour_set, params, workers=workers, progress=progress, executor=executor)
    return BuiltSet(
        surfaces=spooled.spool.get(range(spooled.count)),
        model=spooled.model,
        params=spooled.params,
        working_crs=spooled.working_crs,
        source_crs=spooled.source_crs,
        bad_features=spooled.bad_features,
        name=spooled.name,
        interval=spooled.interval,
        repaired=spooled.repaired,
        inputs=list(spooled.inputs),
    )


def build_into(
    spool: Spool,
    contour_set: ContourSet,
    params: BuildParams | None = None,
    *,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
    executor: Executor | None = None,
) -> SpooledSet:
    """Build the CCS of every contour of ``contour_set`` into ``spool``, then repair crossings block by block.

    Surfaces go to the spool as their chunks come back, and the repair reads one block's surfaces at a time,
    so with a spool on disk (``engine.scratch.DiskSpool``) the build holds the input contours and a few chunks and
    blocks, not every surface (docs/design.md section 6).

    Parameters
    ----------
    spool
        Where the surfaces go, numbered in input order of the contours that could be built.
    contour_set
        Contours in a metric working CRS.
    params
        Build parameters (defaults: 1:50,000 -> 1:500,000).
    workers
        Processes to use; None = one per core, 1 = in this process.
    progress
        Called with (done, total) after each chunk.
    executor
        Where the chunks, the blocks' checks and the rebuilds run (a Dask cluster, see :mod:`engine.parallel`);
        None = a local pool of ``workers`` processes, or this process.
    """
    params = params or BuildParams()
    keep_big_buffers_out_of_the_heap()
    release_free_memory()  # what reading the source freed
    workers = default_workers() if workers is None else max(1, workers)
    # One BLAS thread per worker: OpenBLAS's own threads would fight the worker processes for the cores.
    # A given executor (a Dask cluster) runs the very same chunks and repair tasks; it is the caller's to shut
    # down. The local pool stays open through the crossing repair, whose checks and rebuilds it runs too.
    with _pool(executor, workers, -(-len(contour_set.contours) // CHUNK)) as pool:
        return _build_on(pool, spool, contour_set, params, progress)


def _build_on(
    pool: Executor | None,
    spool: Spool,
    contour_set: ContourSet,
    params: BuildParams,
    progress: ProgressCallback | None,
) -> SpooledSet:
    """:func:`build_into` on ``pool`` (None: this process)."""
    survey = survey_contours(contour_set.contours, pool)
    # The usable contours are read from the set when a chunk needs them: a big source's wait on disk.
    contours = ContourSubset(contour_set.contours, survey.usable)
    model, labels = fit_scale_model(contours, params, survey.features)
    starts = range(0, len(contours), CHUNK)
    tasks = (
        (
            contour_payloads(contours, range(i, min(i + CHUNK, len(contours)))),
            labels[i : i + CHUNK].tolist(),
            params,
            model,
            spool.keeps_pickles,
        )
        for i in starts
    )
    built: list[int] = []  # index into ``contours`` of each surface, by its number in the spool
    boxes: list[NDArray[np.float64]] = []  # (k, 4) boxes of each chunk's surfaces
    pieces = PieceIndex()  # the surfaces' pieces, for the repair's blocks
    failed: list[BadFeature] = []
    total = len(contours)  # contours that passed the check; the rejected ones are reported, not built
    if progress:
        progress(0, total)
    for start, chunk in zip(starts, map_ordered(pool, _build_kept_chunk, tasks), strict=True):
        failed.extend(chunk.failed)
        numbers = range(len(built), len(built) + len(chunk.built))
        spool.put_payloads(zip(numbers, chunk.payloads, strict=True))
        pieces.put_boxes(numbers, chunk.pieces)
        built.extend(start + k for k in chunk.built)
        boxes.append(chunk.bounds)
        if progress:
            progress(min(start + CHUNK, total), total)
    inputs = ContourSubset(contours, built)  # the input of each surface, by its number
    repaired = 0
    if params.resolve_crossings and params.target_mode == "scale" and built:
        with threadpool_limits(1):
            release_free_memory()
            repaired = resolve_crossings(
                spool, np.concatenate(boxes), pieces, inputs, labels[built].tolist(), params, model, pool
            )
    if not built and total:
        raise nothing_to_serve(survey.rejected + failed, total)
    return SpooledSet(
        spool=spool,
        inputs=inputs,
        count=len(built),
        model=model,
        params=params,
        working_crs=contour_set.working_crs,
        source_crs=contour_set.source_crs,
        bad_features=list(contour_set.bad_features) + survey.rejected + failed,
        name=contour_set.name,
        interval=contour_set.interval,
        repaired=repaired,
    )


#: Contours per rebuild task of the crossing repair: a round rebuilds a few hundred at most.
REPAIR_CHUNK = 16

#: Rounds of crossing repair; each halves the target tolerance of the contours involved, the last keeps L0
#: (Ln = L0: the contour no longer moves, so two such contours are as apart as in the input).
REPAIR_FACTORS = (0.5, 0.25, 0.125, 0.0)


def checked_ladder_steps(model: ScaleModel) -> list[int]:
    """Steps (ladder[k], ladder[k + 1]) checked for crossings: every one, so every scale from source to
    target is covered (docs/design.md section 4.8); beyond the target every slice is the target's."""
    return list(range(len(model.ladder) - 1))


def resolve_crossings(
    spool: Spool,
    boxes: NDArray[np.float64],
    pieces: PieceIndex,
    inputs: Sequence[Contour],
    labels: Sequence[int],
    params: BuildParams,
    model: ScaleModel,
    executor: Executor | None = None,
) -> int:
    """Rebuild, with finer targets, the contours whose slices meet a neighbour at some scale; returns how
    many changed.

    Pairs of contours that already touch in the input are left alone: generalization cannot separate
    them and must not be blamed for them. Rounds go on until no new contact is left: a contour rebuilt in
    the last round (Ln = L0, it no longer moves) can still be met by a neighbour that was not involved
    before, and that neighbour then gets the same treatment.

    The check runs block by block (:mod:`engine.ccsm.blocks`: each block's contours against those that can
    reach them, the same pairs as a check of the whole set) and the rebuilds in chunks, both on ``executor``
    when given (a local pool or a Dask cluster), else in this process.

    Parameters
    ----------
    spool
        The surfaces, numbered 0 .. n - 1; rebuilt ones replace theirs.
    boxes, pieces
        (n, 4) each surface's box, and their pieces (both kept up to date here).
    inputs, labels
        Each surface's input contour and regression group.
    """
    steps = checked_ladder_steps(model)
    touches = input_touches(spool)
    cache = NearCache(spool)  # the surfaces read by one check, kept for the next: a re-check reads what was rebuilt
    factors = np.ones(len(inputs))  # the first build uses the full target tolerance
    changed: set[int] = set()
    involved = find_crossings_by_block(
        spool, boxes, pieces, model.ladder, steps, None, executor, touches=touches, cache=cache
    )
    round_ = 0
    while involved:
        factor = REPAIR_FACTORS[min(round_, len(REPAIR_FACTORS) - 1)]
        round_ += 1
        todo = []
        for i in sorted(involved):
            # Never coarser than before, and at least one step finer than its last build.
            new_factor = min(factor, _next_factor(float(factors[i])))
            if factors[i] > new_factor:
                todo.append((i, new_factor))
        rebuilt_now: set[int] = set()
        for numbers, chunk in _rebuild(inputs, labels, todo, params, model, executor, spool.keeps_pickles):
            # A contour whose rebuild failed keeps its surface; the others replace theirs, as built.
            kept = [numbers[k] for k in chunk.built]
            spool.put_payloads(zip(kept, chunk.payloads, strict=True))
            boxes[kept] = chunk.bounds
            pieces.put_boxes(kept, chunk.pieces)
            factors[kept] = chunk.factors
            changed.update(kept)
            rebuilt_now.update(kept)
        cache.forget(rebuilt_now)  # replaced in the spool
        # Only the rebuilt contours can have made new crossings (or still have old ones).
        involved = (
            find_crossings_by_block(
                spool, boxes, pieces, model.ladder, steps, rebuilt_now, executor, touches=touches, cache=cache
            )
            if rebuilt_now
            else set()
        )
    return len(changed)


def _rebuild(
    inputs: Sequence[Contour],
    labels: Sequence[int],
    todo: Sequence[tuple[int, float]],
    params: BuildParams,
    model: ScaleModel,
    executor: Executor | None,
    pickle_surfaces: bool,
) -> Iterator[tuple[list[int], KeptChunk]]:
    """Rebuild contours ``todo`` = (index, tolerance factor), in chunks on ``executor``: each chunk's indices and
    its surfaces as the spool keeps them, as they come (a round can rebuild thousands: neither their inputs nor
    their surfaces are held at once, and the build process neither opens nor measures them)."""
    chunks = [list(todo[k : k + REPAIR_CHUNK]) for k in range(0, len(todo), REPAIR_CHUNK)]
    tasks = (
        (
            contour_payloads(inputs, [i for i, _ in chunk]),
            [labels[i] for i, _ in chunk],
            params,
            model,
            pickle_surfaces,
            [f for _, f in chunk],
        )
        for chunk in chunks
    )
    for chunk, kept in zip(chunks, map_ordered(executor, _build_kept_chunk, tasks), strict=True):
        yield [i for i, _ in chunk], kept


def _next_factor(factor: float) -> float:
    """The first repair factor below ``factor`` (0 once the factors run out)."""
    return next((f for f in REPAIR_FACTORS if f < factor), 0.0)


def t_for_scale_all(built: BuiltSet, scale: float) -> np.ndarray:
    """t of every surface at one scale denominator: (n,) float64."""
    from engine.ccsm.regression import t_for_scale

    return np.array([t_for_scale(built.model.ladder, s.t_at_scale, scale) for s in built.surfaces])
