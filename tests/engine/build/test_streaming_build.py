"""The streaming build (issue 12 item 2): surfaces wait in a scratch file, not in memory; chunks and blocks are
read lazily; the scratch file never outlives its build; the result is the in-memory build's, row for row."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from synthetic_rasters import fractal_heights, write_geotiff

import engine.build.datasets as datasets
import engine.build.labels as build_labels
import engine.ccsm.blocks as blocks
from engine.build.datasets import SourceSpec, build_dataset
from engine.ccsm.build import build_contour_set, build_into
from engine.ccsm.spool import MemorySpool
from engine.errors import StoreError
from engine.parallel import local_pool, map_ordered
from engine.params import BuildParams
from engine.scratch import SCRATCH_PREFIX, DiskSpool, host_name, remove_stale_scratch
from engine.store.store import CCSStore
from tests.app.conftest import write_geojson
from tests.engine.ccsm.test_blocks import ring_clusters


class CountingSpool(MemorySpool):
    """A memory spool that records how many surfaces each read asks for."""

    def __init__(self) -> None:
        super().__init__()
        self.reads: list[int] = []

    def get(self, indices):  # noqa: ANN001, ANN201 - the Spool protocol's
        indices = list(indices)
        self.reads.append(len(indices))
        return super().get(indices)


def test_map_ordered_reads_its_tasks_lazily_and_keeps_a_bounded_number_in_flight() -> None:
    pulled = []
    in_flight_max = [0]
    running = [0]
    lock = threading.Lock()

    def tasks():
        for i in range(40):
            pulled.append(i)
            yield (i,)

    def work(i: int) -> int:
        with lock:
            running[0] += 1
            in_flight_max[0] = max(in_flight_max[0], len(pulled) - i)
        with lock:
            running[0] -= 1
        return i * i

    with ThreadPoolExecutor(4) as pool:
        results = map_ordered(pool, work, tasks(), ahead=3)
        assert pulled == []  # nothing is read before the first result is asked for
        assert next(results) == 0
        assert len(pulled) == 3
        assert list(results) == [i * i for i in range(1, 40)]
    assert in_flight_max[0] <= 3


def test_the_repair_reads_back_one_block_at_a_time_and_decides_as_the_whole_set(monkeypatch) -> None:
    clusters = ring_clusters()
    whole = build_contour_set(clusters, BuildParams(), workers=1)
    monkeypatch.setattr(blocks, "BLOCK_CONTOURS", 5)
    monkeypatch.setattr(blocks, "REBUILT_PER_BLOCK", 5)
    spool = CountingSpool()
    spooled = build_into(spool, clusters, BuildParams(), workers=1)
    assert spooled.repaired == whole.repaired > 10
    n = spooled.count
    # Every read during the build is one block's surfaces (5 own and their near stretches) or one pair's
    # input touch test: never the set, which only the final read in order takes.
    assert spool.reads and max(spool.reads) < n / 2, spool.reads
    for a, b in zip(spool.get(range(n)), whole.surfaces, strict=True):
        assert_array_equal(a.base, b.base)
        assert_array_equal(a.top, b.top)


@pytest.fixture(scope="module")
def clusters_source(tmp_path_factory) -> Path:
    """The ring clusters as a GeoJSON file (WGS 84), so they go through the store build."""
    from pyproj import Transformer

    to_wgs84 = Transformer.from_crs("EPSG:32616", "EPSG:4326", always_xy=True)
    features = []
    for c in ring_clusters().contours:
        lon, lat = to_wgs84.transform(*np.vstack([c.coords, c.coords[:1]]).T)
        features.append(
            {
                "type": "Feature",
                "properties": {"id": f"r{c.id}", "elevation": float(c.elevation)},
                "geometry": {"type": "LineString", "coordinates": np.column_stack([lon, lat]).tolist()},
            }
        )
    return write_geojson(tmp_path_factory.mktemp("clusters") / "clusters.geojson", features)


def small_dem(tmp_path: Path) -> SourceSpec:
    """Dataset "t": a 64 x 64 fractal DEM at 30 m, contoured every 10 m (a few hundred contours, labels too)."""
    z = fractal_heights(11, 3.0, n=64, relief_m=200.0).astype(np.float32)
    dem = write_geotiff(tmp_path / "t.tif", z, west=740_000.0, north=4_060_000.0, cell=30.0, crs="EPSG:32616")
    return SourceSpec(dem, "t", "t", interval=10.0)


def stored_rows(store: CCSStore, dataset: str) -> list[tuple]:
    """The dataset's contour rows in fid order, each with its fid counted from the dataset's first (so two
    stores' rows compare, fids included); never none (a dataset with no row would make comparisons vacuous)."""
    rows = store._con().execute(
        "SELECT fid, contour_id, elevation, base, top, original, t_at_scale, sim, sig, vanish_scale FROM contours "
        "WHERE dataset=? ORDER BY fid",
        (store._rows_of(dataset),),
    ).fetchall()
    assert rows, f"no rows stored for {dataset!r}"
    return [(r[0] - rows[0][0], *r[1:]) for r in rows]


def test_a_store_build_through_the_scratch_file_writes_the_rows_of_an_in_memory_build(
    tmp_path, clusters_source, monkeypatch
) -> None:
    store = CCSStore(tmp_path / "s.sqlite")
    info, _ = build_dataset(store, SourceSpec(clusters_source, "c", "c"), workers=2)
    assert info.n_contours == 45
    streamed = stored_rows(store, "c")

    class InMemory(MemorySpool):
        def __init__(self, directory) -> None:  # noqa: ANN001 - DiskSpool's signature
            super().__init__()

    monkeypatch.setattr(datasets, "DiskSpool", InMemory)
    build_dataset(store, SourceSpec(clusters_source, "m", "m"), workers=1)
    assert stored_rows(store, "m") == streamed
    assert not list(tmp_path.glob(f"{SCRATCH_PREFIX}*"))  # the scratch file went with its build


class RecordingExecutor(Executor):
    """Another executor, with the name of every function submitted to it recorded."""

    def __init__(self, inner: Executor) -> None:
        self.inner = inner
        self.ran: list[str] = []

    def submit(self, fn, /, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN201 - Executor's
        self.ran.append(fn.__name__)
        return self.inner.submit(fn, *args, **kwargs)


def test_rows_and_label_candidates_made_on_an_executor_are_stored_as_made_in_the_build_process(
    tmp_path, monkeypatch
) -> None:
    import engine.store.shard as shard

    spec = small_dem(tmp_path)
    dem = spec.path
    here = CCSStore(tmp_path / "here.sqlite")
    build_dataset(here, spec, workers=1)
    pooled = CCSStore(tmp_path / "pool.sqlite")
    build_dataset(pooled, SourceSpec(dem, "earlier", "earlier", interval=20.0), workers=1)  # fids taken before

    build_process, merge_run = os.getpid(), shard.merge_run

    def on_workers_only(*args: object) -> None:  # the pool's processes are forked with this patch
        assert os.getpid() != build_process, "a shard was merged in the build process"
        merge_run(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(shard, "merge_run", on_workers_only)
    load = CCSStore.load

    def loaded_on_workers_only(self, *args):  # noqa: ANN001, ANN002, ANN202 - CCSStore.load's
        assert os.getpid() != build_process, "contour rows were read in the build process"
        return load(self, *args)

    monkeypatch.setattr(CCSStore, "load", loaded_on_workers_only)  # the labels' rows are read by the workers
    with local_pool(2) as pool:
        executor = RecordingExecutor(pool)
        build_dataset(pooled, spec, executor=executor)
    # The worker processes made the rows, merged them into the store and found the labels' candidates, several
    # tasks of each; the rows take the fids after the earlier dataset's, in input order.
    assert executor.ran.count("batch_shard") > 1 and executor.ran.count("stored_candidates") > 1, executor.ran
    assert stored_rows(pooled, "t") == stored_rows(here, "t")
    assert pooled.all_fids("t")[0] == pooled.all_fids("earlier")[-1] + 1
    mine, theirs = here.labels("t"), pooled.labels("t")
    assert mine is not None and theirs is not None and len(mine.anchors) > 10
    for column in ("xy", "angle", "min_zoom", "rank", "elevation", "box_px"):
        assert_array_equal(getattr(theirs.anchors, column), getattr(mine.anchors, column))
    shift = pooled.all_fids("t")[0] - here.all_fids("t")[0]
    assert_array_equal(theirs.anchors.fid - shift, mine.anchors.fid)
    assert theirs.anchors.text == mine.anchors.text


@pytest.mark.parametrize("unreadable_by", ["block", "shard", "label"])
def test_a_build_whose_workers_cannot_read_its_files_sends_them_the_data_and_stores_the_same_rows(
    tmp_path, monkeypatch, unreadable_by: str
) -> None:
    # A cluster on other machines: no worker can read the spool's file (nor open the store). The first task
    # sent with only where its surfaces lie (a block's check, or a shard's rows when the blocks' reads are let
    # through) comes back unread and goes again with them, and so do the tasks after it; the rows are the same.
    import engine.store.shard as shard
    from engine.payloads import FileSlice, FileUnreachable

    spec = small_dem(tmp_path)
    here = CCSStore(tmp_path / "here.sqlite")
    build_dataset(here, spec, workers=1)
    build_thread = threading.get_ident()
    unread: list[str] = []
    real_fetched = datasets.fetched

    def on_another_machine(items):  # noqa: ANN001, ANN202 - fetched's
        if threading.get_ident() != build_thread and any(isinstance(i, FileSlice) for i in items):
            unread.append(unreadable_by)
            raise FileUnreachable("no such file on this worker")
        return real_fetched(items)

    def rows_on_another_machine(rows, fids):  # noqa: ANN001, ANN202 - _stored_records'
        if threading.get_ident() != build_thread:
            unread.append(unreadable_by)
            raise FileUnreachable("no such file on this worker")
        return read_rows(rows, fids)

    if unreadable_by == "label":
        read_rows = build_labels._stored_records
        monkeypatch.setattr(build_labels, "_stored_records", rows_on_another_machine)
    else:
        monkeypatch.setattr(blocks if unreadable_by == "block" else datasets, "fetched", on_another_machine)
    monkeypatch.setattr(shard, "_holds_reservation", lambda target: False)  # nor the store
    remote = CCSStore(tmp_path / "remote.sqlite")
    with ThreadPoolExecutor(2) as pool:
        executor = RecordingExecutor(pool)
        build_dataset(remote, spec, executor=executor)
    assert stored_rows(remote, "t") == stored_rows(here, "t")
    assert _labels_of(remote, "t") == _labels_of(here, "t")
    assert unread, "no task was sent only where its data lies"
    assert executor.ran.count("batch_shard") > 1 and executor.ran.count("block_contacts") > 1, executor.ran


def _labels_of(store: CCSStore, dataset: str) -> list[tuple]:
    """The dataset's label anchors, one tuple each, with fids counted from the dataset's first."""
    labels = store.labels(dataset)
    assert labels is not None and len(labels.anchors) > 0, "no labels placed"
    a, first = labels.anchors, store.all_fids(dataset)[0]
    columns = zip(a.xy.tolist(), a.angle.tolist(), a.min_zoom.tolist(), (a.fid - first).tolist(), a.text, strict=True)
    return list(columns)


class RecordingPool(RecordingExecutor):
    """A :class:`RecordingExecutor` that shuts its pool down with it, as the build's own pool is."""

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:  # noqa: D102
        self.inner.shutdown(wait=wait, cancel_futures=cancel_futures)


@pytest.mark.parametrize("source", ["dem", "lines"])
def test_a_local_build_makes_its_rows_and_label_candidates_on_its_own_pool(
    tmp_path, monkeypatch, clusters_source, source: str
) -> None:
    # ccsm build --workers 2 with no cluster: the pool it opens must last to the labels, or the rows and the
    # candidates run serially in the build process while the workers wait; a DEM's pool opens before it is read,
    # so its levels are traced on it too.
    import engine.ccsm.build as ccsm_build

    pools: list[RecordingPool] = []

    def recording_pool(workers: int) -> RecordingPool:
        pools.append(RecordingPool(local_pool(workers)))
        return pools[-1]

    monkeypatch.setattr(ccsm_build, "local_pool", recording_pool)
    if source == "dem":
        spec = small_dem(tmp_path)
    else:
        monkeypatch.setattr(ccsm_build, "CHUNK", 8)  # the 45 lines: several chunks of work, so a pool
        spec = SourceSpec(clusters_source, "t", "t")
    build_dataset(CCSStore(tmp_path / "s.sqlite"), spec, workers=2)
    assert len(pools) == 1, "one pool for the whole build"
    ran = pools[0].ran
    assert ran.count("_build_kept_chunk") > 1, ran
    assert ran.count("batch_shard") >= 1 and ran.count("stored_candidates") >= 1, ran
    if source == "dem":
        assert ran.count("batch_shard") > 1 and ran.count("stored_candidates") > 1, ran
    # A DEM read whole is traced on the pool, a run of levels a task; a contour file is read here.
    assert (ran.count("trace_grid_levels") > 1) == (source == "dem"), ran


def test_the_build_process_forwards_contours_and_surfaces_without_opening_them(tmp_path, monkeypatch) -> None:
    # Issue 26: where the build process only passes a contour on (to a chunk's or a shard's task) or a surface
    # (from a chunk's task to the spool), opening and pickling it again was serial work on the hub of the build.
    # It opens only the scale model's reference contours (the survey checks and measures every contour on the
    # pool), and pickles no surface: the repair's rebuilds come back pickled, boxed and cut into pieces too.
    import engine.ccsm.build as ccsm_build
    import engine.io.cleaning as cleaning
    import engine.scratch as scratch
    from engine.ccsm.ccs import CCS
    from engine.ccsm.regression import REFERENCES_PER_GROUP

    here = os.getpid()  # the pool's processes are forked from this one, with the counters patched in
    opened: list[int] = []
    pickled_factors: list[float] = []
    read_range, pickled = scratch.ReadScratch.read_range, scratch.pickled

    def counting_read_range(self, name, start, stop):  # noqa: ANN001, ANN202
        got = read_range(self, name, start, stop)
        if os.getpid() == here and name == cleaning.CONTOURS_LIST:
            opened.extend(range(start, start + len(got)))
        return got

    def counting_pickled(obj):  # noqa: ANN001, ANN202
        if os.getpid() == here and isinstance(obj, CCS):
            pickled_factors.append(obj.tolerance_factor)
        return pickled(obj)

    repaired: list[int] = []
    resolve_crossings = ccsm_build.resolve_crossings

    def counting_repairs(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        repaired.append(resolve_crossings(*args, **kwargs))
        return repaired[-1]

    monkeypatch.setattr(scratch.ReadScratch, "read_range", counting_read_range)
    monkeypatch.setattr(scratch, "pickled", counting_pickled)
    monkeypatch.setattr(ccsm_build, "resolve_crossings", counting_repairs)
    store = CCSStore(tmp_path / "s.sqlite")
    info, _ = build_dataset(store, small_dem(tmp_path), workers=2)
    contours = info.n_contours
    assert contours > 2 * 64, "more than two chunks"
    # Only the scale model's reference contours are opened here: no contour for its check, its size and shape,
    # its chunk, its rebuilds or its shard; no surface is pickled here, though the repair rebuilt some.
    references = BuildParams().groups * REFERENCES_PER_GROUP
    assert 0 < len(opened) <= references, (len(opened), contours)
    assert repaired and repaired[0] > 0, repaired
    assert pickled_factors == [], sorted(set(pickled_factors))
    # What the workers sent is what a build in one process stores.
    alone = CCSStore(tmp_path / "alone.sqlite")
    build_dataset(alone, small_dem(tmp_path), workers=1)
    assert stored_rows(store, "t") == stored_rows(alone, "t")


def test_a_failing_build_removes_its_scratch_file_and_keeps_the_stored_version(
    tmp_path, clusters_source, monkeypatch
) -> None:
    store = CCSStore(tmp_path / "s.sqlite")
    build_dataset(store, SourceSpec(clusters_source, "c", "c"), workers=1)
    before = stored_rows(store, "c")
    seen = []

    def fail(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        seen.extend(tmp_path.glob(f"{SCRATCH_PREFIX}*"))
        raise MemoryError("killed while writing")

    monkeypatch.setattr(datasets, "contour_rows", fail)
    with pytest.raises(MemoryError):
        build_dataset(store, SourceSpec(clusters_source, "c", "c"), workers=1, force=True)
    # The reader's scratch file (the source's contours) and the build's (its surfaces), both beside the store.
    assert len(seen) == 2 and all(p.parent == tmp_path for p in seen)
    assert not list(tmp_path.glob(f"{SCRATCH_PREFIX}*"))
    assert stored_rows(CCSStore(tmp_path / "s.sqlite"), "c") == before


def test_scratch_files_of_dead_builds_are_removed_and_those_of_live_ones_kept(tmp_path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{dead_pid}-abcd.sqlite"
    live = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{os.getpid()}-efgh.sqlite"
    other_host = tmp_path / f"{SCRATCH_PREFIX}elsewhere-{dead_pid}-ijkl.sqlite"
    for path in (stale, live, other_host):
        path.write_bytes(b"x")
    spool = DiskSpool(tmp_path)  # a new build sweeps first
    try:
        assert not stale.exists()
        assert live.exists() and other_host.exists()
        assert spool.path.name.startswith(f"{SCRATCH_PREFIX}{host_name()}-{os.getpid()}-")
    finally:
        spool.close()
    assert not spool.path.exists()
    assert remove_stale_scratch(tmp_path) == []


def test_a_scratch_file_that_cannot_be_made_is_a_clear_store_error(tmp_path) -> None:
    locked = tmp_path / "ro"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores the mode: make the directory a file's path instead
            locked.chmod(0o700)
            locked.rmdir()
            locked.write_text("not a directory")
        with pytest.raises(StoreError, match="scratch file"):
            DiskSpool(locked)
    finally:
        if locked.is_dir():
            locked.chmod(0o700)


def test_label_candidates_read_by_a_worker_from_the_store_are_those_of_the_rows_sent(tmp_path) -> None:
    from engine.build.labels import StoredRows, stored_candidates
    from engine.cartography.dataset import dataset_cartography
    from engine.cartography.labels import LabelStyle
    from engine.payloads import FileUnreachable

    store = CCSStore(tmp_path / "s.sqlite")
    info, _ = build_dataset(store, small_dem(tmp_path), workers=1)
    fids = store.all_fids("t")
    elevations = np.unique([r.elevation for r in store.load(fids)])
    carto = dataset_cartography(info, 10.0, elevations)
    task = (fids, carto, info.ladder, 17.0, LabelStyle())
    sent = stored_candidates(store.load(fids), *task)
    read = stored_candidates(StoredRows(str(store.path), store.rows_id("t")), *task)
    assert len(sent) > 3 and [head for head, _ in read] == [head for head, _ in sent]
    for (_, a), (_, b) in zip(read, sent, strict=True):
        assert not isinstance(a, str) and not isinstance(b, str)
        for column_a, column_b in zip(a, b, strict=True):
            assert_array_equal(column_a, column_b)
    # Another machine: no file there, another store there, or another file.
    other = CCSStore(tmp_path / "other.sqlite")
    (tmp_path / "text.sqlite").write_text("not a store")
    for rows in (
        StoredRows(str(tmp_path / "nowhere.sqlite"), store.rows_id("t")),
        StoredRows(str(other.path), store.rows_id("t")),
        StoredRows(str(tmp_path / "text.sqlite"), store.rows_id("t")),
        StoredRows(str(store.path), "another dataset's rows"),
    ):
        with pytest.raises(FileUnreachable):
            stored_candidates(rows, *task)
