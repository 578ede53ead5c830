"""The survey before a build (issue 26 item 2): every contour checked and measured on the build's workers, a chunk
per task. Which contours are usable, why the others are not, and the size and shape the scale model groups by
must be those of checking them one by one in the build process, in input order, on any mix of contours; and with
workers, the build process checks none."""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal
from synthetic_shapes import noisy_ellipse_coords, noisy_line_coords

import engine.ccsm.survey as survey_module
from engine.ccsm.build import build_contour_set
from engine.ccsm.regression import fit_scale_model, group_features
from engine.ccsm.survey import Survey, survey_contours
from engine.params import BuildParams
from engine.scratch import ReadScratch, ScratchContours
from engine.types import Contour, ContourSet, ContourSubset

#: Kinds of contour a set is drawn from; the good ones can carry a CCS, each bad one for its own reason.
GOOD = ("line", "ring")
BAD = {
    "nan": "NaN or infinite coordinates",
    "inf": "NaN or infinite coordinates",
    "one vertex": "1 vertices, a line needs 2",
    "two-vertex ring": "2 vertices, a ring needs 3",
    "repeated vertex": "repeated consecutive vertices",
    "three columns": "coordinates must have shape (n, 2)",
}


def make_contour(kind: str, k: int, seed: int) -> Contour:
    """Contour ``k`` of a set, of ``kind``, in a cell of its own."""
    offset = np.array([4_000.0 * k, 0.0])
    if kind == "ring":
        return Contour(k, 10.0 * k, noisy_ellipse_coords(seed, a_m=900, b_m=500, n=40) + offset, closed=True)
    xy = noisy_line_coords(seed, n=30) + offset
    if kind == "nan":
        xy[seed % len(xy), 1] = np.nan
    elif kind == "inf":
        xy[seed % len(xy), 0] = np.inf
    elif kind == "one vertex":
        xy = xy[:1]
    elif kind == "two-vertex ring":
        return Contour(k, 10.0 * k, xy[:2], closed=True)
    elif kind == "repeated vertex":
        at = 1 + seed % (len(xy) - 1)
        xy[at] = xy[at - 1]
    elif kind == "three columns":
        xy = np.column_stack([xy, np.zeros(len(xy))])
    return Contour(k, 10.0 * k, xy, closed=False)


kinds = st.lists(st.sampled_from([*GOOD, *BAD]), min_size=0, max_size=40)


@pytest.fixture(scope="module")
def pool() -> Iterator[Executor]:
    # Spawned, not forked: the workers import the code afresh, so what a test patches here stays here.
    with ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn")) as executor:
        yield executor


def assert_same_survey(a: Survey, b: Survey) -> None:
    assert a.usable == b.usable
    assert a.rejected == b.rejected
    assert_array_equal(a.features, b.features)  # bit for bit: the grouping must not move


@settings(deadline=None, max_examples=40)
@given(drawn=kinds, seed=st.integers(0, 2**16), chunk=st.integers(1, 7))
def test_the_survey_on_workers_is_the_check_of_each_contour_in_input_order(
    drawn: list[str], seed: int, chunk: int, pool: Executor
) -> None:
    contours = [make_contour(kind, k, seed + k) for k, kind in enumerate(drawn)]
    with pytest.MonkeyPatch.context() as mp:  # a few contours a task: many tasks, their order kept
        mp.setattr(survey_module, "SURVEY_CHUNK", chunk)
        on_workers = survey_contours(contours, pool)
    here = survey_contours(contours, None)
    assert_same_survey(on_workers, here)
    # What the generator made decides: the good ones are usable, each bad one is named with its own reason.
    assert on_workers.usable == [k for k, kind in enumerate(drawn) if kind in GOOD]
    bad = [(k, kind) for k, kind in enumerate(drawn) if kind not in GOOD]
    assert [r.id for r in on_workers.rejected] == [k for k, _ in bad]
    for rejected, (k, kind) in zip(on_workers.rejected, bad, strict=True):
        assert rejected.reason.startswith(f"contour {k!r}: {BAD[kind]}"), rejected.reason
    # The model groups by the very features it would measure itself.
    usable = [contours[k] for k in on_workers.usable]
    assert on_workers.features.shape == (len(usable), 2)
    assert_array_equal(on_workers.features, group_features(usable))


def test_contours_waiting_on_disk_are_surveyed_as_the_pickles_they_are_kept_as(
    tmp_path: Path, pool: Executor
) -> None:
    drawn = ["ring", "nan", "line", "repeated vertex", *GOOD * 40, "one vertex"]
    contours = [make_contour(kind, k, 7 + k) for k, kind in enumerate(drawn)]
    scratch = ReadScratch(tmp_path)
    try:
        scratch.extend("contours", contours)
        on_disk = ScratchContours(scratch, "contours")
        assert isinstance(on_disk.payloads([0])[0], bytes)  # what the tasks carry: pickles, unopened
        expected = survey_contours(contours, None)
        assert_same_survey(survey_contours(on_disk, pool), expected)
        assert_same_survey(survey_contours(on_disk, None), expected)
    finally:
        scratch.close()
    assert expected.usable == [0, 2, *range(4, 84)]


def test_the_features_give_the_model_it_fits_without_them() -> None:
    drawn = [*GOOD * 30, "nan", "three columns"]
    contours = [make_contour(kind, k, 11 * k) for k, kind in enumerate(drawn)]
    surveyed = survey_contours(contours, None)
    usable = ContourSubset(contours, surveyed.usable)
    params = BuildParams(groups=3)
    with_features, labels = fit_scale_model(usable, params, surveyed.features)
    measured, measured_labels = fit_scale_model(usable, params)
    assert_array_equal(labels, measured_labels)
    assert len(set(labels.tolist())) == 3
    for a, b in zip(with_features.groups, measured.groups, strict=True):
        assert a.reference_id == b.reference_id and a.coefficients == b.coefficients


def test_a_build_with_workers_checks_no_contour_in_the_build_process(
    pool: Executor, monkeypatch: pytest.MonkeyPatch
) -> None:
    drawn = [*GOOD * 20, "nan", "one vertex"]
    contour_set = ContourSet(
        [make_contour(kind, k, 5 + k) for k, kind in enumerate(drawn)],
        working_crs="EPSG:32616",
        source_crs="EPSG:32616",
    )
    here = build_contour_set(contour_set, BuildParams(), workers=1)

    def refuse(*args: object) -> None:
        raise AssertionError("a contour was checked in the build process")

    monkeypatch.setattr(survey_module, "check_contour", refuse)
    monkeypatch.setattr(survey_module, "contour_features", refuse)
    on_workers = build_contour_set(contour_set, BuildParams(), executor=pool)
    assert [s.contour_id for s in on_workers.surfaces] == [s.contour_id for s in here.surfaces] == list(range(40))
    assert on_workers.bad_features == here.bad_features
    assert [b.id for b in here.bad_features] == [40, 41]
    for a, b in zip(on_workers.surfaces, here.surfaces, strict=True):
        assert_array_equal(a.top, b.top)
        assert_array_equal(a.t_at_scale, b.t_at_scale)
