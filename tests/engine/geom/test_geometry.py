"""Tests of engine.geom.polyline: lengths, areas and arc-length resampling, checked against shapely."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from engine.errors import InvalidParameter
from engine.geom.polyline import (
    closed_path,
    cumulative_length,
    path_length,
    points_at_lengths,
    resample_by_arclength,
    ring_area,
    segment_lengths,
)

HYPOTHESIS = settings(deadline=None, max_examples=50)


@st.composite
def random_lines(draw: st.DrawFn) -> np.ndarray:
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(2, 40))
    return np.cumsum(np.random.default_rng(seed).normal(0.0, 25.0, (n, 2)), axis=0) + [750_000.0, 4_060_000.0]


def test_closed_path_repeats_the_first_vertex_at_the_end() -> None:
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert closed_path(ring).tolist() == [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]


def test_segment_and_cumulative_lengths_of_a_3_4_5_path() -> None:
    path = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]])
    assert_allclose(segment_lengths(path), [5.0, 6.0], atol=1e-12)
    assert_allclose(cumulative_length(path), [0.0, 5.0, 11.0], atol=1e-12)


@given(random_lines())
@HYPOTHESIS
def test_path_length_equals_shapely_length(line: np.ndarray) -> None:
    assert path_length(line) == pytest.approx(shapely.LineString(line).length, rel=1e-12)


def test_ring_length_includes_the_closing_segment() -> None:
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    assert path_length(square, closed=True) == pytest.approx(8.0, abs=1e-12)
    assert path_length(square, closed=False) == pytest.approx(6.0, abs=1e-12)


@pytest.mark.parametrize("reverse", [False, True])
def test_ring_area_is_unsigned_and_matches_shapely(reverse: bool) -> None:
    rng = np.random.default_rng(4)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, 25))
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) * rng.uniform(50.0, 90.0, (25, 1))
    if reverse:
        ring = ring[::-1]
    assert ring_area(ring) == pytest.approx(shapely.Polygon(ring).area, rel=1e-12)


def test_points_at_lengths_clamps_to_the_ends() -> None:
    path = np.array([[0.0, 0.0], [10.0, 0.0]])
    got = points_at_lengths(path, cumulative_length(path), np.array([-5.0, 2.5, 15.0]))
    assert_allclose(got, [[0.0, 0.0], [2.5, 0.0], [10.0, 0.0]], atol=1e-12)


@given(random_lines(), st.integers(2, 60))
@HYPOTHESIS
def test_resample_by_arclength_places_points_where_shapely_interpolates(line: np.ndarray, n: int) -> None:
    shape = shapely.LineString(line)
    expected = [shape.interpolate(d).coords[0] for d in np.linspace(0.0, shape.length, n)]
    assert_allclose(resample_by_arclength(line, n), expected, rtol=0, atol=1e-6)


@given(random_lines(), st.integers(2, 60))
@HYPOTHESIS
def test_resample_by_arclength_keeps_both_ends(line: np.ndarray, n: int) -> None:
    out = resample_by_arclength(line, n)
    assert out.shape == (n, 2)
    assert_allclose(out[0], line[0], rtol=0, atol=1e-9)
    assert_allclose(out[-1], line[-1], rtol=0, atol=1e-6)


@given(st.floats(1.0, 1e4), st.floats(0.0, 2 * np.pi), st.integers(2, 80))
@HYPOTHESIS
def test_resample_by_arclength_of_a_straight_line_is_evenly_spaced(
    length: float, angle: float, n: int
) -> None:
    direction = np.array([np.cos(angle), np.sin(angle)])
    # A straight line with uneven vertices: the output must not follow the input's spacing.
    line = np.array([0.0, 0.1, 0.15, 0.8, 1.0])[:, None] * length * direction
    gaps = np.hypot(*np.diff(resample_by_arclength(line, n), axis=0).T)
    assert_allclose(gaps, length / (n - 1), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("n", [1, 0, -2])
def test_resample_by_arclength_rejects_fewer_than_two_points(n: int) -> None:
    with pytest.raises(InvalidParameter):
        resample_by_arclength(np.array([[0.0, 0.0], [1.0, 0.0]]), n)


def test_ring_area_is_accurate_for_a_small_ring_far_from_the_origin() -> None:
    square = np.array([[750_000.0, 4_060_000.0]]) + np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    assert ring_area(square) == pytest.approx(0.01, rel=1e-6)


# -- the compiled measures against the NumPy they replaced, to the last bit ------------------------------------


@settings(deadline=None, max_examples=300)
@given(seed=st.integers(0, 2**32 - 1), n=st.one_of(st.integers(0, 300), st.integers(300, 20_000)))
def test_numpy_sum_is_numpys_sum_bit_for_bit(seed: int, n: int) -> None:
    from engine.geom.kernels import numpy_sum

    rng = np.random.default_rng(seed)
    values = rng.exponential(1.0, n) * 10.0 ** rng.uniform(-8.0, 8.0, n)  # magnitudes wide enough to round
    assert numpy_sum(values) == values.sum()


@st.composite
def lines_with_repeats(draw: st.DrawFn) -> np.ndarray:
    """Lines of 1 to 400 vertices, some repeated (steps of no length), at UTM magnitudes."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.one_of(st.integers(1, 12), st.integers(12, 400)))
    rng = np.random.default_rng(seed)
    line = np.cumsum(rng.normal(0.0, 25.0, (n, 2)), axis=0) + [750_000.0, 4_060_000.0]
    for i in draw(st.lists(st.integers(1, 399), max_size=3)):
        if i < n:
            line[i] = line[i - 1]
    return line


@settings(deadline=None, max_examples=300)
@given(line=lines_with_repeats(), closed=st.booleans())
def test_path_length_is_numpys_sum_of_the_segment_lengths_bit_for_bit(line: np.ndarray, closed: bool) -> None:
    assert path_length(line, closed) == float(segment_lengths(closed_path(line) if closed else line).sum())


@settings(deadline=None, max_examples=300)
@given(line=lines_with_repeats(), count=st.integers(2, 700))
def test_resampling_is_numpys_interpolation_at_linspace_targets_bit_for_bit(line: np.ndarray, count: int) -> None:
    cumlen = cumulative_length(line)
    expected = points_at_lengths(line, cumlen, np.linspace(0.0, cumlen[-1], count))
    assert np.array_equal(resample_by_arclength(line, count), expected)


def test_resampling_refuses_a_line_with_no_vertices() -> None:
    with pytest.raises(InvalidParameter, match="no vertices"):
        resample_by_arclength(np.zeros((0, 2)), 3)
