"""The crossing repair block by block (issue 12 item 2): the same contacts, the same decisions as over the whole set."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from numpy.testing import assert_array_equal

import engine.ccsm.blocks as blocks
from engine.ccsm.blocks import PieceIndex, find_crossings_by_block, spatial_blocks, surface_boxes
from engine.ccsm.build import BuiltSet, build_contour_set, checked_ladder_steps
from engine.ccsm.ccs import CCS
from engine.ccsm.spool import MemorySpool
from engine.ccsm.topology import InputTouches, find_new_crossings
from engine.params import BuildParams
from engine.types import Contour, ContourSet


def ring_clusters(side: int = 3, rings: int = 5, seed: int = 7) -> ContourSet:
    """``side`` x ``side`` clusters of nested noisy rings 20 m apart (their DP targets cross), 2.1 km apart
    so the boxes of neighbouring clusters' outer rings overlap: many blocks, and contours reaching into others."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 2 * np.pi, 160, endpoint=False)
    contours = []
    for cx in range(side):
        for cy in range(side):
            centre = np.array([500_000.0 + 2_100.0 * cx, 4_000_000.0 + 1_300.0 * cy])
            for k in range(rings):
                r = 1_000.0 + 20.0 * k + rng.uniform(-6.0, 6.0, len(s))
                xy = np.column_stack([r * np.cos(s), 0.6 * r * np.sin(s)]) + centre
                contours.append(Contour(len(contours), 100.0 + 20 * k, xy, closed=True))
    return ContourSet(contours, "EPSG:32616", "EPSG:32616")


@pytest.fixture(scope="module")
def clusters() -> ContourSet:
    return ring_clusters()


@pytest.fixture(scope="module")
def unrepaired(clusters: ContourSet) -> BuiltSet:
    return build_contour_set(clusters, BuildParams(resolve_crossings=False), workers=1)


def random_lines(n: int = 300, seed: int = 1) -> list[CCS]:
    """Random wiggly open lines of 20-80 points whose top rows are their base rows moved a little."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        m = int(rng.integers(20, 80))
        start = rng.uniform(0, 1_000, 2)
        base = start + np.cumsum(rng.normal(0, 4, (m, 2)), axis=0)
        top = base + rng.normal(0, 1, (m, 2))
        out.append(CCS(i, 0.0, False, base, top, np.zeros(1), np.ones(1), 1.0, m, m))
    return out


def lines_with_tables_of_their_own() -> list[CCS]:
    """:func:`random_lines`, each with its own t table and vanishing scale: a stretch cut from one must carry its
    own surface's, which the contact check reads with its rows."""
    from dataclasses import replace

    return [
        replace(s, t_at_scale=np.linspace(0.0, 1.0, 5) ** (1 + i % 7), vanish_scale=1e5 + i)
        for i, s in enumerate(random_lines())
    ]


def test_every_segment_is_owned_once_and_its_block_holds_every_stretch_that_can_meet_it() -> None:
    surfaces = random_lines()
    boxes = surface_boxes(surfaces)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    found = spatial_blocks(boxes, pieces, per_block=8)
    assert len(found) > 10

    def spans(b, which):  # (contour, first row, last row) of the block's own or other stretches
        return [
            (i, 0, len(surfaces[i].base) - 1) if f < 0 else (i, f, la)
            for i, f, la, o in zip(b.near.tolist(), b.first.tolist(), b.last.tolist(), b.own.tolist(), strict=True)
            if o == which
        ]

    owned = [np.zeros(len(s.base) - 1, dtype=int) for s in surfaces]
    for b in found:
        for i, f, la in spans(b, True):
            owned[i][f:la] += 1
    assert all((o == 1).all() for o in owned)  # every segment of every contour is in one block's own stretches
    # Reference: every segment's swept box against every own segment of the block.
    segments = []
    for s in surfaces:
        rows = np.stack([s.base, s.top], axis=1)
        lo, hi = rows.min(axis=1), rows.max(axis=1)
        segments.append(shapely.box(*np.minimum(lo[:-1], lo[1:]).T, *np.maximum(hi[:-1], hi[1:]).T))
    cut_somewhere = several = split_own = False
    for b in found:
        own = spans(b, True)
        split_own |= any(la - f + 1 < len(surfaces[i].base) for i, f, la in own)
        stretches: dict[int, list[tuple[int, int]]] = {}
        for i, f, la in own + spans(b, False):
            stretches.setdefault(i, []).append((f, la))
        for i, f, la in own:
            tree = shapely.STRtree(segments[i][f:la])
            for j in set(range(len(surfaces))) - {i}:
                touching = np.flatnonzero([len(tree.query(g)) > 0 for g in segments[j]])
                if not len(touching):
                    continue
                assert j in stretches, f"contour {j} reaches contour {i} rows {f}-{la} but is not near it"
                for k in touching.tolist():  # segment k (rows k, k + 1) lies in one of j's stretches
                    assert any(f2 <= k and k + 1 <= la2 for f2, la2 in stretches[j]), f"{j} segment {k} left out"
                cut_somewhere |= sum(la2 - f2 + 1 for f2, la2 in stretches[j]) < len(surfaces[j].base)
                several |= len(stretches[j]) > 1
    assert cut_somewhere  # the stretches really are cut to the blocks
    assert several  # and a contour that comes near in two places is checked in both, not in between
    assert split_own  # a contour longer than a cell is owned in pieces by the cells it crosses


def test_blocks_find_the_same_contacts_as_the_whole_set(unrepaired: BuiltSet) -> None:
    surfaces = unrepaired.surfaces
    ladder = unrepaired.model.ladder
    steps = checked_ladder_steps(unrepaired.model)
    whole = find_new_crossings(surfaces, ladder, steps, InputTouches([s.at(0.0) for s in surfaces]))
    assert len(whole) > 10  # the DP targets of the rings cross: there is something to find
    spool = MemorySpool()
    for i, s in enumerate(surfaces):
        spool.put(i, s)
    boxes = surface_boxes(surfaces)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    assert find_crossings_by_block(spool, boxes, pieces, ladder, steps, per_block=4) == whole
    only = set(range(0, len(surfaces), 3))
    with_only = find_new_crossings(surfaces, ladder, steps, InputTouches([s.at(0.0) for s in surfaces]), only)
    assert find_crossings_by_block(spool, boxes, pieces, ladder, steps, only, per_block=4) == with_only


@pytest.fixture(scope="module")
def repaired_whole(clusters: ContourSet) -> BuiltSet:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(blocks, "BLOCK_CONTOURS", 10**9)  # one block: the whole set at once
        return build_contour_set(clusters, BuildParams(), workers=1)


@pytest.mark.parametrize("workers", [1, 2])
def test_repair_by_small_blocks_makes_the_surfaces_of_the_repair_over_the_whole_set(
    clusters: ContourSet, repaired_whole: BuiltSet, workers: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(blocks, "BLOCK_CONTOURS", 4)
    by_block = build_contour_set(clusters, BuildParams(), workers=workers)
    assert repaired_whole.repaired > 10
    assert by_block.repaired == repaired_whole.repaired
    for a, b in zip(by_block.surfaces, repaired_whole.surfaces, strict=True):
        assert_array_equal(a.base, b.base)
        assert_array_equal(a.top, b.top)
        assert_array_equal(a.t_at_scale, b.t_at_scale)
    surfaces, model = by_block.surfaces, by_block.model
    left = find_new_crossings(
        surfaces, model.ladder, checked_ladder_steps(model), InputTouches([s.at(0.0) for s in surfaces])
    )
    assert left == set()


def test_a_block_task_carries_whole_surfaces_as_stored_and_stretches_cut(tmp_path) -> None:

    from engine.ccsm.blocks import NearStretch, _block_tasks
    from engine.ccsm.spool import surface_of
    from engine.scratch import DiskSpool

    # Each surface its own t table and vanishing scale: a stretch must carry its own surface's, which the
    # contact check reads with its rows.
    surfaces = lines_with_tables_of_their_own()
    spool = DiskSpool(tmp_path)
    spool.put_many(enumerate(surfaces))
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    found = spatial_blocks(surface_boxes(surfaces), pieces, per_block=8)
    cut = 0
    for b, (near, own, *_) in zip(found, _block_tasks(found, spool, np.ones(2), [0]), strict=True):
        assert own == np.flatnonzero(b.own).tolist()
        for k, (i, f, la) in enumerate(zip(b.near.tolist(), b.first.tolist(), b.last.tolist(), strict=True)):
            s = surface_of(near[k])
            whole = surfaces[i]
            if f < 0:
                assert isinstance(near[k], bytes)  # shipped as stored, opened in the worker
                np.testing.assert_array_equal(s.base, whole.base)
            else:
                assert isinstance(near[k], NearStretch)  # its rows and what the check reads, not a whole CCS
                np.testing.assert_array_equal(s.base, whole.base[f : la + 1])
                np.testing.assert_array_equal(s.top, whole.top[f : la + 1])
                np.testing.assert_array_equal(s.t_at_scale, whole.t_at_scale)
                assert s.vanish_scale == whole.vanish_scale
                cut += len(s.base) < len(whole.base)
    spool.close()
    assert cut > 0


@pytest.mark.parametrize("budget", [0, 20_000, 1 << 30])
def test_block_tasks_are_the_same_whatever_the_near_cache_keeps(tmp_path, monkeypatch, budget: int) -> None:
    """Neighbouring blocks share near surfaces, kept between blocks up to a byte budget: every task's rows are
    the spool's whatever is kept (nothing kept, some evicted, all kept), and with room for all each surface is
    read once."""
    from engine.ccsm.blocks import _block_tasks
    from engine.ccsm.spool import surface_of
    from engine.scratch import DiskSpool

    surfaces = random_lines()
    spool = DiskSpool(tmp_path)
    spool.put_many(enumerate(surfaces))
    reads: list[int] = []
    read = spool.get_payloads
    monkeypatch.setattr(spool, "get_payloads", lambda indices: reads.extend(indices) or read(indices))
    monkeypatch.setattr(blocks, "NEAR_CACHE_BYTES", budget)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    found = spatial_blocks(surface_boxes(surfaces), pieces, per_block=8)
    for b, (near, *_) in zip(found, _block_tasks(found, spool, np.ones(2), [0]), strict=True):
        for k, (i, f, la) in enumerate(zip(b.near.tolist(), b.first.tolist(), b.last.tolist(), strict=True)):
            rows = slice(None) if f < 0 else slice(f, la + 1)
            np.testing.assert_array_equal(surface_of(near[k]).base, surfaces[i].base[rows])
            np.testing.assert_array_equal(surface_of(near[k]).top, surfaces[i].top[rows])
    spool.close()
    every = {i for b in found for i in b.near.tolist()}
    if budget == 1 << 30:
        assert sorted(reads) == sorted(every)
    else:
        assert len(reads) > len(every)  # read again once evicted


def test_a_near_cache_kept_across_checks_reads_what_was_replaced(tmp_path) -> None:
    """The repair keeps one cache of surfaces across its checks: a surface replaced in the spool and forgotten
    is read again (a re-check must see the rebuilt rows), the others are not, and its bytes stay counted."""
    from engine.ccsm.blocks import NearCache
    from engine.ccsm.spool import surface_of
    from engine.scratch import DiskSpool

    surfaces = random_lines(20)
    spool = DiskSpool(tmp_path)
    spool.put_many(enumerate(surfaces))
    reads: list[int] = []
    read = spool.get_payloads
    spool.get_payloads = lambda indices: reads.extend(indices) or read(indices)  # type: ignore[method-assign]
    cache = NearCache(spool)
    cache.payloads(list(range(20)))
    cache.surface(3)
    moved = replace_rows(surfaces[3], surfaces[3].base + 100.0)
    spool.put(3, moved)
    cache.forget([3])
    reads.clear()
    assert_array_equal(surface_of(cache.payloads([2, 3])[1]).base, moved.base)
    assert_array_equal(cache.surface(3).base, moved.base)
    assert reads == [3]
    cache.forget(range(20))
    assert cache.size == 0 and not cache.items
    spool.close()


def replace_rows(surface: CCS, base: np.ndarray) -> CCS:
    """The surface with other base and top rows (as a rebuild gives)."""
    from dataclasses import replace

    return replace(surface, base=base, top=base + 1.0)


def test_repair_with_the_near_cache_kept_across_checks_makes_the_surfaces_of_one_that_keeps_nothing(
    clusters: ContourSet, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The repair's cache of surfaces outlives its checks: its re-checks must see the rebuilt surfaces, so the
    build is the one with nothing kept between blocks (a stale surface would be found crossing again)."""
    monkeypatch.setattr(blocks, "BLOCK_CONTOURS", 4)
    kept = build_contour_set(clusters, BuildParams(), workers=1)
    monkeypatch.setattr(blocks, "NEAR_CACHE_BYTES", 0)
    fresh = build_contour_set(clusters, BuildParams(), workers=1)
    assert fresh.repaired > 10
    assert kept.repaired == fresh.repaired
    for a, b in zip(kept.surfaces, fresh.surfaces, strict=True):
        assert_array_equal(a.base, b.base)
        assert_array_equal(a.top, b.top)


def test_block_tasks_for_workers_carry_where_surfaces_lie_and_the_worker_cuts_the_same_stretches(tmp_path) -> None:

    from engine.ccsm.blocks import NearSlice, _block_tasks, near_surfaces
    from engine.payloads import FileSlice
    from engine.scratch import DiskSpool

    surfaces = lines_with_tables_of_their_own()
    spool = DiskSpool(tmp_path)
    spool.put_many(enumerate(surfaces))
    reads: list[int] = []
    read = spool.get_payloads
    spool.get_payloads = lambda indices: reads.extend(indices) or read(indices)  # type: ignore[method-assign]
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    found = spatial_blocks(surface_boxes(surfaces), pieces, per_block=8)
    cut = 0
    for b, (near, own, *_) in zip(found, _block_tasks(found, spool, np.ones(2), [0], sliced=True), strict=True):
        assert own == np.flatnonzero(b.own).tolist()
        opened_there = near_surfaces(near)  # what the worker does with them
        for k, (i, f, la) in enumerate(zip(b.near.tolist(), b.first.tolist(), b.last.tolist(), strict=True)):
            s, whole = opened_there[k], surfaces[i]
            rows = slice(None) if f < 0 else slice(f, la + 1)
            assert isinstance(near[k], FileSlice if f < 0 else NearSlice)
            np.testing.assert_array_equal(s.base, whole.base[rows])
            np.testing.assert_array_equal(s.top, whole.top[rows])
            np.testing.assert_array_equal(s.t_at_scale, whole.t_at_scale)
            assert s.vanish_scale == whole.vanish_scale
            cut += len(s.base) < len(whole.base)
    assert cut > 0 and reads == []  # the build process read none of the surfaces
    spool.close()


def _disk_spool_of(surfaces: list[CCS], directory) -> object:  # noqa: ANN001 - a path
    from engine.scratch import DiskSpool

    spool = DiskSpool(directory)
    spool.put_many(enumerate(surfaces))
    return spool


def test_blocks_checked_on_a_pool_that_reads_the_spool_find_the_contacts_of_one_process(
    unrepaired: BuiltSet, tmp_path
) -> None:
    from engine.parallel import local_pool

    surfaces, ladder = unrepaired.surfaces, unrepaired.model.ladder
    steps = checked_ladder_steps(unrepaired.model)
    boxes = surface_boxes(surfaces)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    here = find_crossings_by_block(_disk_spool_of(surfaces, tmp_path), boxes, pieces, ladder, steps, per_block=4)
    assert len(here) > 10
    spool = _disk_spool_of(surfaces, tmp_path)
    # The build process reads no surface: not a block's, nor the base rows of a pair found for the input's touch
    # test (the workers answer it, having both whole surfaces).

    def read_here(indices):  # noqa: ANN001, ANN202 - the spool's
        raise AssertionError(f"surfaces {indices} were read in the build process")

    spool.get, spool.get_payloads = read_here, read_here
    with local_pool(2) as pool:
        assert find_crossings_by_block(spool, boxes, pieces, ladder, steps, executor=pool, per_block=4) == here


def test_the_workers_answers_to_the_input_touch_test_are_the_build_process_ones(
    tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Random wiggly lines: many cross one another already in the input (those pairs are left alone).
    from engine.ccsm import topology
    from engine.parallel import local_pool

    surfaces = random_lines(200, seed=3)
    ladder = np.geomspace(50_000.0, 500_000.0, 5)
    for s in surfaces:
        s.t_at_scale = np.linspace(0.0, 1.0, len(ladder))
    steps = list(range(len(ladder) - 1))
    boxes = surface_boxes(surfaces)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)

    def found(executor=None):  # noqa: ANN001, ANN202
        spool = _disk_spool_of(surfaces, tmp_path)
        return find_crossings_by_block(spool, boxes, pieces, ladder, steps, executor=executor, per_block=4)

    with local_pool(2) as pool:
        on_workers = found(pool)
    monkeypatch.setattr(topology.InputTouches, "record", lambda self, answers: None)  # every pair asked here
    asked_here = found()
    assert on_workers == asked_here
    # The answers matter on this data: some pairs found do touch in the input, and are left alone.
    monkeypatch.setattr(topology.InputTouches, "__contains__", lambda self, pair: False)
    assert found() > asked_here


def test_blocks_whose_workers_cannot_read_the_spool_are_sent_again_with_their_surfaces(
    unrepaired: BuiltSet, tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import threading
    from concurrent.futures import Executor, ThreadPoolExecutor

    from engine.ccsm.blocks import NearSlice
    from engine.payloads import FileSlice, FileUnreachable

    surfaces, ladder = unrepaired.surfaces, unrepaired.model.ladder
    steps = checked_ladder_steps(unrepaired.model)
    boxes = surface_boxes(surfaces)
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    here = find_crossings_by_block(_disk_spool_of(surfaces, tmp_path), boxes, pieces, ladder, steps, per_block=4)
    build_process, real_fetched = threading.get_ident(), blocks.fetched

    def on_another_machine(items):  # noqa: ANN001, ANN202 - fetched's
        if threading.get_ident() != build_process and any(isinstance(i, FileSlice) for i in items):
            raise FileUnreachable("no such file on this worker")
        return real_fetched(items)

    monkeypatch.setattr(blocks, "fetched", on_another_machine)
    sent: list[str] = []

    class Recording(Executor):
        def __init__(self, inner: Executor) -> None:
            self.inner = inner

        def submit(self, fn, /, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN201 - Executor's
            sliced = any(isinstance(item, (FileSlice, NearSlice)) for item in args[0])
            sent.append("where they lie" if sliced else "surfaces")
            return self.inner.submit(fn, *args, **kwargs)

    spool = _disk_spool_of(surfaces, tmp_path)
    with ThreadPoolExecutor(2) as pool:
        found = find_crossings_by_block(spool, boxes, pieces, ladder, steps, executor=Recording(pool), per_block=4)
    assert found == here
    # The first tasks went as slices and came back unread; each went again with its surfaces, and from then on
    # every task carried its surfaces.
    assert sent[0] == "where they lie" and sent[-1] == "surfaces"
    assert "where they lie" not in sent[sent.index("surfaces") :][sent.count("where they lie") :]
    assert spool.get_slices([0]) is None


@pytest.mark.parametrize("budget", [0, 1 << 30])
def test_a_worker_keeps_the_surfaces_it_opened_for_its_next_blocks(tmp_path, monkeypatch, budget: int) -> None:
    """A long contour is near many blocks: a worker reads and opens it once while its budget lasts, and every
    block's stretches are the spool's whatever is kept (nothing kept: read again each time)."""
    from engine.ccsm.blocks import NearSlice, OpenedSlices, _block_tasks, near_surfaces

    surfaces = random_lines()
    spool = _disk_spool_of(surfaces, tmp_path)
    monkeypatch.setattr(blocks, "OPENED_NEAR", OpenedSlices())
    monkeypatch.setattr(blocks, "OPENED_NEAR_BYTES", budget)
    reads: list[object] = []
    real_fetched = blocks.fetched
    monkeypatch.setattr(blocks, "fetched", lambda items: reads.extend(items) or real_fetched(items))
    pieces = PieceIndex()
    pieces.put(range(len(surfaces)), surfaces)
    found = spatial_blocks(surface_boxes(surfaces), pieces, per_block=8)
    asked = 0
    for b, (near, *_) in zip(found, _block_tasks(found, spool, np.ones(2), [0], sliced=True), strict=True):
        asked += len(near)
        for k, (i, f, la, s) in enumerate(
            zip(b.near.tolist(), b.first.tolist(), b.last.tolist(), near_surfaces(near), strict=True)
        ):
            rows = slice(None) if f < 0 else slice(f, la + 1)
            assert isinstance(near[k], NearSlice) == (f >= 0)
            np.testing.assert_array_equal(s.base, surfaces[i].base[rows])
            np.testing.assert_array_equal(s.top, surfaces[i].top[rows])
    every = {i for b in found for i in b.near.tolist()}
    if budget:
        assert len(reads) == len(every)  # each surface read once
    else:
        # Nothing kept but the last block's: each block reads those of its surfaces the block before did not
        # have (one read for two stretches of one surface).
        held: set[int] = set()
        expected = 0
        for b in found:
            now = set(b.near.tolist())
            expected += len(now - held)
            held = now
        assert len(reads) == expected > len(every)
        assert asked >= len(reads)
    spool.close()
