"""Contract of engine.baselines: ladder() and simplify_at_scale() for dp, wm and vw, and their errors."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from engine.baselines import BASELINE_METHODS, effective_areas, ladder, simplify_at_scale
from engine.baselines.common import count_schedule
from engine.errors import InvalidContour, InvalidParameter
from engine.geom.douglas_peucker import douglas_peucker, douglas_peucker_count
from engine.tolerances import tolerance_for_scale
from engine.types import Contour

HYPOTHESIS = settings(deadline=None, max_examples=40)


def random_walk(seed: int, n: int, closed: bool) -> np.ndarray:
    """A seeded noisy contour in metres: a random walk heading east, or a star-shaped noisy ring."""
    rng = np.random.default_rng(seed)
    if closed:
        angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
        radius = 500.0 * (1.0 + 0.25 * np.sin(3.0 * angle) + 0.08 * rng.standard_normal(n))
        return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    x = np.cumsum(rng.uniform(5.0, 40.0, n))
    y = np.cumsum(rng.normal(0.0, 12.0, n))
    return np.column_stack([x, y])


def row_set(xy: np.ndarray) -> set[tuple[float, float]]:
    return {(float(x), float(y)) for x, y in xy}


def is_subsequence(small: np.ndarray, big: np.ndarray) -> bool:
    """Whether the rows of ``small`` appear in ``big`` in the same order."""
    it = iter(map(tuple, big))
    return all(any(row == other for other in it) for row in map(tuple, small))


CASES = [(m, closed, seed) for m in BASELINE_METHODS for closed in (False, True) for seed in (1, 2, 3)]


@pytest.mark.parametrize(("method", "closed", "seed"), CASES)
def test_ladder_shape_and_ends(method: str, closed: bool, seed: int) -> None:
    xy = random_walk(seed, 120, closed)
    levels = ladder(method, xy, closed, levels=100)
    assert len(levels) == 100
    assert_array_equal(levels[0], xy)
    counts = [len(level) for level in levels]
    assert all(a >= b for a, b in zip(counts, counts[1:], strict=False)), counts
    assert counts[-1] == (3 if closed else 2)
    for level in levels:
        assert level.dtype == np.float64 and level.ndim == 2 and level.shape[1] == 2
        if not closed:
            assert_array_equal(level[0], xy[0])
            assert_array_equal(level[-1], xy[-1])


@pytest.mark.parametrize(("method", "closed", "seed"), CASES)
def test_ladder_levels_are_nested_input_vertices(method: str, closed: bool, seed: int) -> None:
    # DP and VW by construction; the WM ladder only eliminates bends, so it keeps input vertices too.
    xy = random_walk(seed, 90, closed)
    levels = ladder(method, xy, closed, levels=30)
    source = row_set(xy)
    for finer, coarser in zip(levels, levels[1:], strict=False):
        assert row_set(coarser) <= source
        assert is_subsequence(coarser, finer)


@pytest.mark.parametrize("method", ["dp", "vw"])
@pytest.mark.parametrize("closed", [False, True])
def test_point_ladders_follow_the_one_percent_schedule(method: str, closed: bool) -> None:
    xy = random_walk(4, 157, closed)
    counts = [len(level) for level in ladder(method, xy, closed)]
    assert counts == count_schedule(157, 3 if closed else 2, 100).tolist()
    # 1 % of the points per level: consecutive levels differ by (n - floor) / 99, rounded.
    steps = np.diff(counts)
    assert set(steps.tolist()) <= {-1, -2}


@pytest.mark.parametrize("closed", [False, True])
def test_dp_ladder_equals_douglas_peucker_count(closed: bool) -> None:
    xy = random_walk(5, 80, closed)
    for level in ladder("dp", xy, closed, levels=25):
        assert_array_equal(level, xy[douglas_peucker_count(xy, len(level), closed)])


def test_ladder_on_shared_fixtures(noisy_open_line: Contour, noisy_ellipse_ring: Contour) -> None:
    # Far from the origin (UTM metres), as real contours are.
    for contour in (noisy_open_line, noisy_ellipse_ring):
        for method in BASELINE_METHODS:
            levels = ladder(method, contour.coords, contour.closed)
            assert_array_equal(levels[0], contour.coords)
            assert len(levels[-1]) == (3 if contour.closed else 2)


@given(
    seed=st.integers(0, 10_000),
    n=st.integers(3, 60),
    levels=st.integers(2, 40),
    closed=st.booleans(),
    method=st.sampled_from(BASELINE_METHODS),
)
@HYPOTHESIS
def test_ladder_invariants_hold_for_any_size(
    seed: int, n: int, levels: int, closed: bool, method: str
) -> None:
    xy = random_walk(seed, n, closed)
    out = ladder(method, xy, closed, levels=levels)
    assert len(out) == levels
    assert_array_equal(out[0], xy)
    counts = [len(level) for level in out]
    assert counts == sorted(counts, reverse=True)
    assert counts[-1] == min(n, 3 if closed else 2)
    assert row_set(out[-1]) <= row_set(xy)


def test_closed_ring_with_repeated_first_vertex_is_the_same_ring() -> None:
    xy = random_walk(6, 40, closed=True)
    repeated = np.vstack([xy, xy[:1]])
    for method in BASELINE_METHODS:
        a = ladder(method, xy, True, levels=10)
        b = ladder(method, repeated, True, levels=10)
        for x, y in zip(a, b, strict=True):
            assert_array_equal(x, y)


def test_outputs_do_not_alias_the_input() -> None:
    xy = random_walk(7, 30, closed=False)
    keep = xy.copy()
    for method in BASELINE_METHODS:
        out = ladder(method, xy, False, levels=5)
        out[0][:] = 0.0
        simplify_at_scale(method, xy, False, 100_000)[:] = 0.0
    assert_array_equal(xy, keep)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("scale", [25_000, 100_000, 500_000])
def test_dp_at_scale_uses_the_0_1_mm_tolerance(closed: bool, scale: float) -> None:
    xy = random_walk(8, 200, closed)
    expected = xy[douglas_peucker(xy, tolerance_for_scale(scale), closed)]
    assert_array_equal(simplify_at_scale("dp", xy, closed, scale), expected)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("scale", [25_000, 100_000, 500_000])
def test_vw_at_scale_uses_epsilon_squared(closed: bool, scale: float) -> None:
    xy = random_walk(9, 200, closed)
    eps = tolerance_for_scale(scale)
    out = simplify_at_scale("vw", xy, closed, scale)
    assert_array_equal(out, xy[effective_areas(xy, closed) > eps * eps])
    assert len(out) >= (3 if closed else 2)


@pytest.mark.parametrize("method", ["dp", "vw"])
@pytest.mark.parametrize("closed", [False, True])
def test_point_methods_keep_fewer_vertices_at_smaller_scales(method: str, closed: bool) -> None:
    xy = random_walk(10, 300, closed)
    results = [simplify_at_scale(method, xy, closed, s) for s in (10_000, 50_000, 250_000, 1_000_000)]
    for finer, coarser in zip(results, results[1:], strict=False):
        assert is_subsequence(coarser, finer)


@pytest.mark.parametrize("closed", [False, True])
def test_wm_at_scale_keeps_the_minimum(closed: bool) -> None:
    xy = random_walk(11, 150, closed)
    out = simplify_at_scale("wm", xy, closed, 50_000_000)
    assert len(out) >= (3 if closed else 2)
    if not closed:
        assert_array_equal(out[[0, -1]], xy[[0, -1]])


# --- errors ------------------------------------------------------------------------------------------------

LINE = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])


@pytest.mark.parametrize("method", ["DP", "ccsm", "", None, 3])
def test_unknown_method_is_rejected(method: object) -> None:
    with pytest.raises(InvalidParameter, match=f"method.*{re.escape(repr(method))}"):
        ladder(method, LINE, False)  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match=f"method.*{re.escape(repr(method))}"):
        simplify_at_scale(method, LINE, False, 50_000)  # type: ignore[arg-type]


@pytest.mark.parametrize("levels", [1, 0, -5, 2.5, True, "100", None])
def test_bad_levels_are_rejected(levels: object) -> None:
    with pytest.raises(InvalidParameter, match=f"levels.*{re.escape(repr(levels))}"):
        ladder("dp", LINE, False, levels=levels)  # type: ignore[arg-type]


@pytest.mark.parametrize("scale", [0, -1, -50_000.0, math.nan, math.inf, True, "50000"])
def test_bad_scales_are_rejected(scale: object) -> None:
    for method in BASELINE_METHODS:
        with pytest.raises(InvalidParameter, match=f"scale.*{re.escape(repr(scale))}"):
            simplify_at_scale(method, LINE, False, scale)  # type: ignore[arg-type]


def test_numpy_integers_are_valid_parameters() -> None:
    assert len(ladder("vw", LINE, False, levels=np.int64(3))) == 3
    assert len(simplify_at_scale("dp", LINE, False, np.float32(1e5))) == 2


@pytest.mark.parametrize("coords", [np.zeros((4, 3)), np.zeros(8), np.zeros((2, 2, 2))])
def test_bad_shapes_are_rejected(coords: np.ndarray) -> None:
    with pytest.raises(InvalidParameter, match="shape"):
        ladder("dp", coords, False)


@pytest.mark.parametrize(
    ("coords", "closed"),
    [
        (np.array([[0.0, 0.0]]), False),
        (np.array([[0.0, 0.0], [1.0, 0.0]]), True),
        (np.array([[0.0, 0.0], [math.nan, 1.0], [2.0, 0.0]]), False),
        (np.array([[0.0, 0.0], [math.inf, 1.0], [2.0, 0.0]]), True),
    ],
)
def test_unusable_contours_are_rejected(coords: np.ndarray, closed: bool) -> None:
    for method in BASELINE_METHODS:
        with pytest.raises(InvalidContour):
            ladder(method, coords, closed)
        with pytest.raises(InvalidContour):
            simplify_at_scale(method, coords, closed, 50_000)


@pytest.mark.parametrize("method", BASELINE_METHODS)
def test_minimal_inputs_stay_minimal(method: str) -> None:
    line = np.array([[0.0, 0.0], [5.0, 1.0]])
    tri = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]])
    for xy, closed in ((line, False), (tri, True)):
        for level in ladder(method, xy, closed, levels=4):
            assert_array_equal(level, xy)
        assert_array_equal(simplify_at_scale(method, xy, closed, 1e9), xy)
