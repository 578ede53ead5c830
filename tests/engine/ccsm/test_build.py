"""Tests of engine.ccsm.build: building a whole contour set, in one process or several."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal
from synthetic_shapes import circle_coords, noisy_ellipse_coords, noisy_line_coords

from engine.ccsm.build import BuiltSet, build_contour_set, vanish_scale
from engine.ccsm.ccs import CCS, build_ccs
from engine.ccsm.regression import ScaleModel
from engine.geom.polyline import ring_areas
from engine.params import BuildParams
from engine.tolerances import MIN_VISIBLE_RING_SIDE_M
from engine.types import Contour, ContourSet

PARAMS = BuildParams()


def synthetic_set(n: int = 200) -> ContourSet:
    """``n`` seeded contours of four kinds, each in its own 5 km cell so that none touch."""
    rng = np.random.default_rng(3)
    contours = []
    for i in range(n):
        cell = np.array([5_000.0 * (i % 20), 5_000.0 * (i // 20)])
        kind = i % 4
        if kind == 0:
            xy = noisy_ellipse_coords(i, a_m=rng.uniform(300, 1500), b_m=rng.uniform(200, 900), n=60)
        elif kind == 1:
            xy = noisy_line_coords(i, n=60)
        elif kind == 2:
            xy = circle_coords(rng.uniform(3.0, 15.0), 8)
        else:
            xy = circle_coords(rng.uniform(1_000.0, 2_000.0), 40)
        contours.append(Contour(i, float(i), xy + cell, closed=kind != 1))
    return ContourSet(contours, working_crs="EPSG:32616", source_crs="EPSG:32616")


@pytest.fixture(scope="module")
def contour_set() -> ContourSet:
    return synthetic_set()


@pytest.fixture(scope="module")
def built_one(contour_set: ContourSet) -> BuiltSet:
    return build_contour_set(contour_set, PARAMS, workers=1)


@pytest.fixture(scope="module")
def built_two(contour_set: ContourSet) -> BuiltSet:
    return build_contour_set(contour_set, PARAMS, workers=2)


def test_every_good_contour_is_built_in_input_order(built_one: BuiltSet, contour_set: ContourSet) -> None:
    assert [s.contour_id for s in built_one.surfaces] == [c.id for c in contour_set.contours]
    assert built_one.bad_features == []


def test_one_and_two_workers_give_identical_surfaces(built_one: BuiltSet, built_two: BuiltSet) -> None:
    assert len(built_one.surfaces) == len(built_two.surfaces)
    for a, b in zip(built_one.surfaces, built_two.surfaces, strict=True):
        assert a.contour_id == b.contour_id
        assert_array_equal(a.base, b.base)
        assert_array_equal(a.top, b.top)
        assert_array_equal(a.sim, b.sim)
        assert_array_equal(a.t_at_scale, b.t_at_scale)
        assert a.vanish_scale == b.vanish_scale and a.group == b.group


def test_each_surface_gets_a_monotone_t_table_over_the_ladder(built_one: BuiltSet) -> None:
    for s in built_one.surfaces:
        assert s.t_at_scale.shape == built_one.model.ladder.shape
        assert s.t_at_scale[0] == 0.0 and s.t_at_scale[-1] == 1.0
        assert np.all(np.diff(s.t_at_scale) >= 0.0)


BAD_COORDS = {
    "repeated": (np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 2.0]]), False),
    "one-vertex": (np.array([[0.0, 0.0]]), False),
    "two-vertex-ring": (np.array([[0.0, 0.0], [5.0, 5.0]]), True),
}


@pytest.mark.parametrize("kind", sorted(BAD_COORDS))
def test_bad_contour_is_reported_by_id_and_the_rest_are_built(kind: str) -> None:
    good = synthetic_set(8).contours
    coords, closed = BAD_COORDS[kind]
    bad = Contour("broken", 0.0, coords, closed=closed)
    contours = good[:4] + [bad] + good[4:]
    built = build_contour_set(ContourSet(contours, "EPSG:32616", "EPSG:32616"), PARAMS, workers=1)
    assert [s.contour_id for s in built.surfaces] == [c.id for c in good]
    assert [b.id for b in built.bad_features] == ["broken"]
    assert "broken" in built.bad_features[0].reason


def test_contour_with_nan_coordinates_is_reported_and_the_rest_are_built() -> None:
    good = synthetic_set(8).contours
    bad = Contour("broken", 0.0, np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]]), closed=False)
    built = build_contour_set(ContourSet(good + [bad], "EPSG:32616", "EPSG:32616"), PARAMS, workers=1)
    assert [s.contour_id for s in built.surfaces] == [c.id for c in good]
    assert [b.id for b in built.bad_features] == ["broken"]


def test_reader_bad_features_are_kept() -> None:
    from engine.types import BadFeature

    cs = synthetic_set(3)
    cs.bad_features.append(BadFeature("from-reader", "no elevation"))
    built = build_contour_set(cs, PARAMS, workers=1)
    assert [b.id for b in built.bad_features] == ["from-reader"]


@pytest.mark.parametrize("workers", [1, 2])
def test_progress_is_reported_up_to_the_total(workers: int) -> None:
    cs = synthetic_set(140)  # more than two chunks of 64
    calls: list[tuple[int, int]] = []
    build_contour_set(cs, PARAMS, workers=workers, progress=lambda done, total: calls.append((done, total)))
    assert calls[0] == (0, 140)
    assert calls[-1] == (140, 140)
    done = [d for d, _ in calls]
    assert done == sorted(done)
    assert all(total == 140 for _, total in calls)


def test_tiny_ring_gets_a_finite_vanish_scale_equal_to_its_visibility_limit(tiny_ring: Contour) -> None:
    built = build_contour_set(ContourSet([tiny_ring], "EPSG:32616", "EPSG:32616"), PARAMS, workers=1)
    area = shapely.Polygon(tiny_ring.coords).area
    # A 5 m ring of 70.7 m² is below (0.5 mm x S)² already at the source scale:
    # it vanishes at sqrt(area) / 0.5 mm.
    assert built.surfaces[0].vanish_scale == pytest.approx(math.sqrt(area) / 0.0005, rel=1e-4)
    assert built.surfaces[0].vanish_scale < PARAMS.source_scale


def test_small_rings_vanish_and_large_rings_and_lines_do_not_before_the_target(built_one: BuiltSet) -> None:
    for s in built_one.surfaces:
        kind = int(s.contour_id) % 4
        if kind == 1:
            assert s.vanish_scale == math.inf
        elif kind == 2:
            assert math.isfinite(s.vanish_scale) and s.vanish_scale < PARAMS.target_scale
        elif kind == 3:
            assert s.vanish_scale >= PARAMS.target_scale


def test_vanish_scale_between_source_and_target_is_the_first_ladder_scale_where_it_is_too_small() -> None:
    # Square of side 40 m: visible at 1:50,000 (0.5 mm is 25 m there); its slices shrink towards a triangle.
    square = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 40.0], [0.0, 40.0]])
    ccs = build_ccs(Contour("sq", 0.0, square, closed=True), PARAMS)
    ladder = np.geomspace(PARAMS.source_scale, PARAMS.target_scale, 33)
    ccs.t_at_scale = np.log(ladder / ladder[0]) / np.log(ladder[-1] / ladder[0])
    too_small = [
        shapely.Polygon(ccs.at(float(t))).area < (0.0005 * s) ** 2
        for s, t in zip(ladder, ccs.t_at_scale, strict=True)
    ]
    expected = ladder[too_small.index(True)]
    scale = vanish_scale(ccs, ScaleModel(PARAMS.source_scale, PARAMS.target_scale, ladder, ()))
    assert scale == pytest.approx(expected, rel=1e-12)
    assert PARAMS.source_scale < scale < PARAMS.target_scale


def vanish_scale_by_every_slice(ccs: CCS, model: ScaleModel) -> float:
    """vanish_scale's rule between source and target scale, stated with NumPy: every ladder slice's area at
    once, the first below its threshold."""
    t = np.clip(ccs.t_at_scale, 0.0, 1.0)[:, None, None]
    areas = ring_areas((1.0 - t) * ccs.base[:-1] + t * ccs.top[:-1])
    small = np.flatnonzero(areas < (MIN_VISIBLE_RING_SIDE_M * model.ladder) ** 2)
    if len(small):
        return float(model.ladder[small[0]])
    return max(model.target_scale, math.sqrt(ring_areas(ccs.top[None, :-1])[0]) / MIN_VISIBLE_RING_SIDE_M)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    vertices=st.integers(3, 80),
    size_m=st.floats(1.0, 3000.0),
    shrink=st.floats(0.0, 1.2),
    tie_at=st.one_of(st.none(), st.integers(0, 31)),
)
def test_vanish_scale_is_the_first_ladder_slice_below_its_threshold_as_numpy_finds_it(
    seed: int, vertices: int, size_m: float, shrink: float, tie_at: int | None
) -> None:
    # Rings at UTM magnitudes shrinking (or not) towards a drawn top; ``tie_at`` puts a ladder scale exactly where
    # its slice's area meets the threshold, which only NumPy's own sums can settle.
    rng = np.random.default_rng(seed)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, vertices))
    radius = size_m * rng.uniform(0.5, 1.0, vertices)
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) * radius[:, None] + [650_000.0, 5_100_000.0]
    top = ring.mean(axis=0) + (ring - ring.mean(axis=0)) * shrink + rng.normal(0.0, size_m / 50, ring.shape)
    base, top = np.vstack([ring, ring[:1]]), np.vstack([top, top[:1]])
    ladder = np.geomspace(PARAMS.source_scale, PARAMS.target_scale, 32)
    t = np.sort(rng.uniform(-0.1, 1.1, 32))
    ccs = CCS("r", 0.0, True, base, top, np.array([0.0, 1.0]), np.array([1.0, 0.9]), 1.0, vertices, 3, t_at_scale=t)
    if tie_at is not None:
        tk = np.clip(t[tie_at], 0.0, 1.0)
        area = ring_areas(((1.0 - tk) * base[:-1] + tk * top[:-1])[None])[0]
        ladder[tie_at] = math.sqrt(area) / MIN_VISIBLE_RING_SIDE_M
    model = ScaleModel(PARAMS.source_scale, PARAMS.target_scale, ladder, ())
    if math.sqrt(ring_areas(base[None, :-1])[0]) / MIN_VISIBLE_RING_SIDE_M <= PARAMS.source_scale:
        return  # too small at the source scale: decided before any ladder slice
    assert vanish_scale(ccs, model) == vanish_scale_by_every_slice(ccs, model)


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), vertices=st.integers(3, 300), at=st.integers(0, 7))
def test_the_compiled_area_pass_never_calls_a_slice_at_its_threshold_other_than_numpy_does(
    seed: int, vertices: int, at: int
) -> None:
    # A threshold equal to NumPy's own area of that slice: NumPy calls it not small; the compiled pass, whose
    # sums round differently, must say so too or say it cannot tell (-2), never call it small.
    from engine.geom.kernels import first_small_slice

    rng = np.random.default_rng(seed)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, vertices))
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) * rng.uniform(50.0, 100.0, (vertices, 1))
    base = ring + [650_000.0, 5_100_000.0]
    top = base + rng.normal(0.0, 5.0, base.shape)
    t = np.sort(rng.uniform(0.0, 1.0, 8))
    areas = ring_areas((1.0 - t[:, None, None]) * base + t[:, None, None] * top)
    thresholds = areas / 2.0  # every slice clearly big enough...
    thresholds[at] = areas[at]  # ...but one exactly at its area
    assert first_small_slice(base, top, t, thresholds) in (-1, -2)
    thresholds[at] = np.nextafter(areas[at], np.inf)  # one unit above: NumPy calls it small
    assert first_small_slice(base, top, t, thresholds) in (at, -2)


def test_built_set_carries_the_crs_and_name(built_one: BuiltSet) -> None:
    assert built_one.working_crs == "EPSG:32616" and built_one.source_crs == "EPSG:32616"
    assert built_one.params == PARAMS
