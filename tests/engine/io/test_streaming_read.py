"""Issue 12 item 2: a big source is read into a scratch file, a level or a batch at a time, and the build takes
its contours from there; the result is that of a read held in memory, contour for contour."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from synthetic_rasters import fractal_heights, write_geotiff

from engine.ccsm.blocks import PieceIndex
from engine.ccsm.build import build_contour_set
from engine.io.source import read_source
from engine.parallel import map_ordered
from engine.params import BuildParams
from engine.payloads import opened
from engine.scratch import SCRATCH_PREFIX, ReadScratch, ScratchContours
from engine.types import Contour, ContourSet, ContourSubset, contour_payloads
from tests.engine.ccsm.test_blocks import ring_clusters

WEST, NORTH, CELL = 740_000.0, 4_060_000.0, 30.0


@pytest.fixture(scope="module")
def dem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rough terrain with a few hundred lines on many levels (and a few node artefacts to report)."""
    z = fractal_heights(5, 3.0, n=192, relief_m=600.0).astype(np.float32)
    return write_geotiff(
        tmp_path_factory.mktemp("dem") / "dem.tif", z, west=WEST, north=NORTH, cell=CELL, crs="EPSG:32616"
    )


def same_sets(a: ContourSet, b: ContourSet) -> None:
    assert (a.working_crs, a.source_crs, a.interval, a.name) == (b.working_crs, b.source_crs, b.interval, b.name)
    assert a.bad_features == b.bad_features
    assert len(a.contours) == len(b.contours)
    for ca, cb in zip(a.contours, b.contours, strict=True):
        assert (ca.id, ca.elevation, ca.closed) == (cb.id, cb.elevation, cb.closed)
        np.testing.assert_array_equal(ca.coords, cb.coords)


@pytest.mark.parametrize("block", [None, 40])
def test_a_dem_read_through_a_scratch_file_gives_the_contours_of_a_read_in_memory(tmp_path, dem, block) -> None:
    in_memory = read_source(dem, interval=10.0, block=block)
    scratch = ReadScratch(tmp_path)
    try:
        spooled = read_source(dem, interval=10.0, block=block, scratch=scratch)
        assert isinstance(spooled.contours, ScratchContours)  # read from the file, not held
        assert len(in_memory.contours) > 300
        same_sets(spooled, in_memory)
        # Every level's pieces and every checked batch were let go once used: only the contours stay.
        listed = {name for (name,) in scratch._con.execute("SELECT DISTINCT list FROM items")}
        assert listed == {"contours"}
    finally:
        scratch.close()
    assert not list(tmp_path.glob(f"{SCRATCH_PREFIX}*"))


def test_a_contour_file_read_through_a_scratch_file_gives_the_contours_of_a_read_in_memory(tmp_path) -> None:
    from engine.io.sample import sample_contours_path

    scratch = ReadScratch(tmp_path)
    try:
        same_sets(read_source(sample_contours_path(), scratch=scratch), read_source(sample_contours_path()))
    finally:
        scratch.close()


def test_reading_a_dem_through_a_scratch_file_holds_a_fraction_of_its_lines(tmp_path, dem) -> None:
    """The lines of the whole DEM are never in memory at once: the read's peak of Python and NumPy memory is
    well under that of a read held in memory (whose contours alone are the size of the lines)."""

    def peak(scratch: ReadScratch | None) -> int:
        tracemalloc.start()
        try:
            contour_set = read_source(dem, interval=5.0, block=48, scratch=scratch)
            assert len(contour_set.contours) > 500
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    held = peak(None)
    scratch = ReadScratch(tmp_path)
    try:
        streamed = peak(scratch)
    finally:
        scratch.close()
    assert streamed < held / 4, f"peak {streamed / 1e6:.1f} MB streamed against {held / 1e6:.1f} MB held"


def test_a_build_from_scratch_contours_equals_a_build_from_a_list(tmp_path) -> None:
    clusters = ring_clusters()
    scratch = ReadScratch(tmp_path)
    try:
        scratch.extend("contours", clusters.contours)
        on_disk = ContourSet(ScratchContours(scratch, "contours"), clusters.working_crs, clusters.source_crs)
        a = build_contour_set(on_disk, BuildParams(), workers=1)
        b = build_contour_set(clusters, BuildParams(), workers=1)
    finally:
        scratch.close()
    assert a.repaired == b.repaired > 0  # the repair's rebuilds read their inputs from the file too
    for sa, sb, ia, ib in zip(a.surfaces, b.surfaces, a.inputs, b.inputs, strict=True):
        np.testing.assert_array_equal(sa.top, sb.top)
        np.testing.assert_array_equal(ia.coords, ib.coords)


def test_a_contour_subset_reads_as_the_list_it_stands_for() -> None:
    contours = [Contour(k, float(k), np.full((2, 2), float(k)), False) for k in range(20)]
    positions = [1, 2, 5, 6, 7, 13, 19]
    subset = ContourSubset(contours, positions)
    expected = [contours[p] for p in positions]
    assert len(subset) == len(expected)
    assert list(subset) == expected
    for s in (slice(0, 3), slice(2, 6), slice(5, 50), slice(4, 4), slice(None, None, 2)):
        assert subset[s] == expected[s]
    assert subset[-1] is contours[19] and subset[3] is contours[6]


@settings(max_examples=60, deadline=None)
@given(
    count=st.integers(0, 40),
    data=st.data(),
)
def test_contour_payloads_are_the_contours_a_read_gives_as_stored(tmp_path_factory, count, data) -> None:
    # What a build forwards to a worker unopened must open to the very contour an ordinary read gives, for any
    # positions (a chunk's run, the repair's scattered rebuilds), through a subset of a subset as a build has.
    contours = [
        Contour(f"c{k}", float(k), np.arange(2 * (k + 2), dtype=np.float64).reshape(-1, 2), k % 3 == 0)
        for k in range(count)
    ]
    outer = sorted(data.draw(st.sets(st.integers(0, max(0, count - 1)), max_size=count)) if count else [])
    inner = sorted(data.draw(st.sets(st.integers(0, max(0, len(outer) - 1)), max_size=len(outer))) if outer else [])
    wanted = data.draw(st.lists(st.integers(0, max(0, len(inner) - 1)), max_size=12) if inner else st.just([]))
    scratch = ReadScratch(tmp_path_factory.mktemp("payloads"))
    try:
        scratch.extend("contours", contours)
        for source in (contours, ScratchContours(scratch, "contours")):
            subset = ContourSubset(ContourSubset(source, outer), inner)
            got = contour_payloads(subset, wanted)
            expected = [contours[outer[inner[w]]] for w in wanted]
            assert all(isinstance(p, bytes) for p in got) == (source is not contours or not got)
            for payload, contour in zip(got, expected, strict=True):
                back = opened(payload)
                assert (back.id, back.elevation, back.closed) == (contour.id, contour.elevation, contour.closed)
                np.testing.assert_array_equal(back.coords, contour.coords)
            assert len(got) == len(expected)
            run = list(range(len(inner)))  # a chunk's consecutive run, read in one range
            assert [opened(p).id for p in contour_payloads(subset, run)] == [c.id for c in subset]
    finally:
        scratch.close()


def test_the_piece_index_after_rebuilds_is_that_of_the_final_surfaces() -> None:
    built = build_contour_set(ring_clusters(), BuildParams(resolve_crossings=False), workers=1)
    surfaces = built.surfaces
    index = PieceIndex()
    for k in range(0, len(surfaces), 7):
        index.put(range(k, min(k + 7, len(surfaces))), surfaces[k : k + 7])
    # Replace a few surfaces by others of another length, out of order, twice for one of them.
    final = list(surfaces)
    for i, j in ((30, 2), (3, 40), (30, 11)):
        final[i] = surfaces[j]
        index.put([i], [surfaces[j]])
    fresh = PieceIndex()
    fresh.put(range(len(final)), final)
    for got, want in zip(index.arrays(), fresh.arrays(), strict=True):
        np.testing.assert_array_equal(got, want)


def test_map_ordered_reads_no_new_task_while_those_in_flight_weigh_the_budget() -> None:
    from concurrent.futures import ThreadPoolExecutor

    weights = [5, 1, 1, 9, 1, 1, 1, 4, 4, 4, 1, 1]
    pulled: list[int] = []
    worst = [0]

    def tasks():
        for i, w in enumerate(weights):
            pulled.append(i)
            yield (i, w)

    def work(i: int, w: int) -> int:
        return i

    with ThreadPoolExecutor(4) as pool:
        results = map_ordered(pool, work, tasks(), ahead=100, weight=lambda t: t[1], budget=6)
        for i in results:
            # Tasks read but not yet yielded (i itself included): never more than the budget plus one task.
            worst[0] = max(worst[0], sum(weights[i : len(pulled)]))
            assert i == len(pulled) - 1 or sum(weights[i : len(pulled) - 1]) < 6
    assert worst[0] <= 6 + max(weights)
    assert pulled == list(range(len(weights)))


def test_freed_big_buffers_go_back_to_the_system() -> None:
    """With glibc's default thresholds, freeing a 16 MB buffer raises the mmap threshold, so the 4 MB buffers
    made next are carved from the heap, and a small block made after each pins them there once freed; with the
    build's settings they are mapped apart and returned whole."""
    probe = """
import sys
from engine.heap import keep_big_buffers_out_of_the_heap
def rss():
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmRSS")) // 1024
if sys.argv[1] == "tuned":
    assert keep_big_buffers_out_of_the_heap()
before = rss()
first = b"x" * (16 << 20)
del first
bufs, kept = [], []
for _ in range(6):
    bufs.append(b"x" * (4 << 20))
    kept.append(b"y" * 2000)
del bufs
print(rss() - before)
"""
    grown = {}
    for mode in ("default", "tuned"):
        out = subprocess.run([sys.executable, "-c", probe, mode], capture_output=True, text=True, check=True)
        grown[mode] = int(out.stdout)
    assert grown["default"] >= 20, grown  # the probe shows the growth it guards against
    assert grown["tuned"] < 4, grown


@pytest.mark.parametrize("suffix", [".gpkg", ".shp", ".geojson"])
def test_issue_12_a_contour_file_read_in_batches_never_holds_its_lines_whole(tmp_path, monkeypatch, suffix) -> None:
    """Through a scratch file, a contour file (GeoPackage, Shapefile, GeoJSON) read a batch of features at a time
    peaks at a fraction of the Python and NumPy memory of one read of every feature (WKB, geometries, coordinates)."""
    import shapely
    from pyogrio.raw import write

    import engine.io.cleaning as cleaning
    import engine.io.vector_reader as vector

    rng = np.random.default_rng(7)
    n, k = 2000, 100  # lines of k vertices, wandering east of (WEST, NORTH)
    steps = rng.normal(0.0, 20.0, (n, k, 2)).cumsum(axis=1)
    starts = np.column_stack([WEST + 50.0 * np.arange(n), np.full(n, NORTH)])[:, None, :]
    wkb = np.asarray(shapely.to_wkb(shapely.linestrings(starts + steps)), dtype=object)
    path = tmp_path / f"lines{suffix}"
    write(path, wkb, [np.full(n, 100.0)], ["ele"], crs="EPSG:32616", geometry_type="LineString")
    monkeypatch.setattr(cleaning, "ASSEMBLE_BATCH_VERTICES", 10_000)
    monkeypatch.setattr(vector, "ARROW_BATCH_FEATURES", 16)  # GDAL's batches as small against the file

    def peak() -> int:
        scratch = ReadScratch(tmp_path)
        tracemalloc.start()
        try:
            assert len(read_source(path, scratch=scratch).contours) == n
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
            scratch.close()

    batched = peak()
    monkeypatch.setattr(vector, "READ_VERTICES", 1 << 40)  # one read of every feature
    whole = peak()
    assert batched < whole / 4, f"peak {batched / 1e6:.1f} MB in batches against {whole / 1e6:.1f} MB whole"
