"""A DEM read whole is traced on the build's workers, a run of levels per task, and its lines checked in its CRS
there (issue 26 item 2): the lines, their ids and order, and the features left out are exactly those of tracing
and checking it in the build process, on any terrain, and the build process itself traces and checks no level."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from terrain_strategies import KINDS, PLACES, TERRAIN_SETTINGS, TerrainCase

import engine.io.cleaning as cleaning
import engine.io.dem as dem
from engine.errors import SourceError
from engine.io.dem import contours_from_dem, trace_grid_levels
from engine.types import ContourSet


@pytest.fixture(scope="module")
def pool() -> Iterator[Executor]:
    # Spawned, not forked: the workers import the code afresh, so what a test patches here stays here.
    with ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn")) as executor:
        yield executor


def traced(path: Path, interval: float, executor: Executor | None) -> ContourSet | str:
    """The contour set of the DEM, or the message of the error reading it gives."""
    try:
        return contours_from_dem(path, interval=interval, executor=executor)
    except SourceError as exc:
        return str(exc)


def assert_identical(a: ContourSet | str, b: ContourSet | str) -> None:
    assert type(a) is type(b), (a, b)
    if isinstance(a, str):
        assert a == b
        return
    assert isinstance(b, ContourSet)
    assert [(c.id, c.elevation, c.closed) for c in a.contours] == [(c.id, c.elevation, c.closed) for c in b.contours]
    for ca, cb in zip(a.contours, b.contours, strict=True):
        np.testing.assert_array_equal(ca.coords, cb.coords)  # bit for bit, not to a tolerance
    assert a.bad_features == b.bad_features
    assert (a.working_crs, a.source_crs, a.interval) == (b.working_crs, b.source_crs, b.interval)


dems = st.builds(
    TerrainCase,
    kind=st.sampled_from(sorted(KINDS)),
    seed=st.integers(0, 2**16),
    n=st.integers(40, 120),
    place=st.sampled_from(sorted(PLACES)),
    as_lines=st.just(False),
)


@TERRAIN_SETTINGS
@given(case=dems, per_task=st.integers(1, 5))
def test_levels_traced_on_workers_are_the_lines_traced_here(
    case: TerrainCase, per_task: int, pool: Executor, tmp_path_factory: pytest.TempPathFactory
) -> None:
    path = case.write(tmp_path_factory.mktemp("dem"))
    here = traced(path, case.interval, None)
    with pytest.MonkeyPatch.context() as mp:  # a few levels a task: many tasks, their order kept
        mp.setattr(dem, "MIN_LEVELS_PER_TASK", per_task)
        mp.setattr(dem, "LEVEL_TASKS", 1000)
        on_workers = traced(path, case.interval, pool)
    assert_identical(on_workers, here)


def write_terrain(folder: Path) -> tuple[Path, float]:
    case = TerrainCase("nodata", 11, 120, sorted(PLACES)[0], False)
    return case.write(folder), case.interval


def test_the_build_process_neither_traces_nor_checks_a_level_when_it_has_workers(
    tmp_path: Path, pool: Executor, monkeypatch: pytest.MonkeyPatch
) -> None:
    path, interval = write_terrain(tmp_path)
    here = traced(path, interval, None)
    assert isinstance(here, ContourSet) and len(here.contours) > 20

    def refuse_tracing(*args: object) -> None:
        raise AssertionError("a level was traced in the build process")

    def refuse_checking(*args: object) -> None:
        raise AssertionError("lines were checked in their CRS in the build process")

    monkeypatch.setattr(dem, "iter_levels", refuse_tracing)
    monkeypatch.setattr(cleaning, "_check_in_source_crs", refuse_checking)
    assert_identical(traced(path, interval, pool), here)


def test_a_worker_refuses_a_dem_that_changed_after_the_build_read_it(tmp_path: Path) -> None:
    path, _ = write_terrain(tmp_path)
    stat = path.stat()
    levels = [100.0, 120.0]
    assert trace_grid_levels(str(path), levels, (stat.st_size, stat.st_mtime_ns))  # as read: traced
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    with pytest.raises(SourceError, match=f"{path.name}: the DEM changed while it was being traced"):
        trace_grid_levels(str(path), levels, (stat.st_size, stat.st_mtime_ns))
    with pytest.raises(SourceError, match="missing.tif: the DEM cannot be read on this worker"):
        trace_grid_levels(str(tmp_path / "missing.tif"), levels, (stat.st_size, stat.st_mtime_ns))


def test_a_window_a_worker_cannot_read_fails_with_the_file_named(tmp_path: Path) -> None:
    from rasterio.windows import Window

    from engine.io.dem_windows import trace_window

    path, _ = write_terrain(tmp_path)
    traced_window, zmin, zmax = trace_window(str(path), Window(0, 0, 40, 40), 20.0)
    assert traced_window and zmin < zmax  # the file as the build read it
    path.write_bytes(b"not a raster any more")
    with pytest.raises(SourceError, match=f"{path.name}: the file could not be read as a DEM"):
        trace_window(str(path), Window(0, 0, 40, 40), 20.0)
    with pytest.raises(SourceError, match="gone.tif: the file could not be read as a DEM"):
        trace_window(str(tmp_path / "gone.tif"), Window(0, 0, 40, 40), 20.0)


def test_workers_in_another_directory_find_a_dem_named_relative_to_the_build(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A Dask worker runs in a directory of its own: a DEM named relative to the build's directory must reach it
    # as the file the build read, for a grid read whole and one read in windows alike.
    path, interval = write_terrain(tmp_path)
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as elsewhere:
        assert elsewhere.submit(os.getcwd).result() != str(tmp_path)  # started before the build moves
        monkeypatch.chdir(tmp_path)
        for block in (None, 50):
            here = contours_from_dem(Path(path.name), interval=interval, block=block)
            on_worker = contours_from_dem(Path(path.name), interval=interval, block=block, executor=elsewhere)
            assert_identical(on_worker, here)
