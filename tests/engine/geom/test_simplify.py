"""Tests of engine.geom.douglas_peucker: Douglas–Peucker for lines and rings, significance and count variants."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from engine.errors import InvalidParameter
from engine.geom.douglas_peucker import douglas_peucker, douglas_peucker_count, ring_anchors, significance
from engine.geom.kernels import dp_significance

HYPOTHESIS = settings(deadline=None, max_examples=60)


# --- plain-Python reference -------------------------------------------------------------------------------


def _point_segment_distance(p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    """Distance of p to the segment a-b (to a itself when the segment is a point)."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    px, py = p[0] - ax, p[1] - ay
    seg2 = dx * dx + dy * dy
    if seg2 > 0.0:
        u = min(1.0, max(0.0, (px * dx + py * dy) / seg2))
        px, py = px - u * dx, py - u * dy
    return math.sqrt(px * px + py * py)


def reference_dp(points: list[tuple[float, float]], eps: float) -> list[int]:
    """Textbook recursive Douglas–Peucker (distance to the chord as a segment), kept indices ascending."""
    keep = {0, len(points) - 1}

    def recurse(first: int, last: int) -> None:
        best, best_i = -1.0, -1
        for i in range(first + 1, last):
            d = _point_segment_distance(points[i], points[first], points[last])
            if d > best:
                best, best_i = d, i
        if best_i >= 0 and best > eps:
            keep.add(best_i)
            recurse(first, best_i)
            recurse(best_i, last)

    recurse(0, len(points) - 1)
    return sorted(keep)


# --- strategies -------------------------------------------------------------------------------------------


@st.composite
def random_lines(
    draw: st.DrawFn, min_points: int = 2, max_points: int = 25, grid: bool = False
) -> np.ndarray:
    """A seeded random polyline; on a small integer grid it has ties, collinear and repeated vertices."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(min_points, max_points))
    rng = np.random.default_rng(seed)
    if grid:
        return rng.integers(0, 6, size=(n, 2)).astype(float)
    return np.cumsum(rng.normal(0.0, 10.0, size=(n, 2)), axis=0)


@st.composite
def random_rings(draw: st.DrawFn) -> np.ndarray:
    """A seeded star-shaped ring (4 to 30 vertices, radii 20-100 m), counter-clockwise."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(4, 30))
    rng = np.random.default_rng(seed)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
    radius = rng.uniform(20.0, 100.0, n)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


epsilons = st.floats(0.0, 60.0, allow_nan=False)


# --- open lines -------------------------------------------------------------------------------------------


def test_docstring_example_keeps_the_spike_and_drops_the_small_wiggle() -> None:
    line = np.array([[0, 0], [1, 0.1], [2, 0], [3, 5], [4, 0.0]])
    assert douglas_peucker(line, 0.5).tolist() == [0, 2, 3, 4]


@given(random_lines(grid=True), epsilons)
@HYPOTHESIS
def test_dp_output_is_an_ascending_subset_of_indices(line: np.ndarray, eps: float) -> None:
    keep = douglas_peucker(line, eps)
    assert np.all(np.diff(keep) > 0)
    assert keep.min() >= 0 and keep.max() < len(line)


@given(random_lines(grid=True), epsilons)
@HYPOTHESIS
def test_dp_keeps_both_endpoints_of_an_open_line(line: np.ndarray, eps: float) -> None:
    keep = douglas_peucker(line, eps)
    assert keep[0] == 0 and keep[-1] == len(line) - 1


@pytest.mark.parametrize("grid", [False, True])
@given(data=st.data())
@HYPOTHESIS
def test_dp_dropped_vertices_lie_within_epsilon_of_the_simplified_line(
    grid: bool, data: st.DataObject
) -> None:
    line = data.draw(random_lines(min_points=3, grid=grid))
    eps = data.draw(epsilons)
    keep = douglas_peucker(line, eps)
    simplified = shapely.LineString(line[keep]) if len(keep) > 1 else shapely.Point(line[keep[0]])
    dropped = np.setdiff1d(np.arange(len(line)), keep)
    for i in dropped:
        assert shapely.Point(line[i]).distance(simplified) <= eps + 1e-9


@given(random_lines(grid=True), epsilons, epsilons)
@HYPOTHESIS
def test_dp_larger_epsilon_keeps_a_subset(line: np.ndarray, eps_a: float, eps_b: float) -> None:
    small, large = sorted((eps_a, eps_b))
    assert set(douglas_peucker(line, large)) <= set(douglas_peucker(line, small))


@given(random_lines(max_points=20), epsilons)
@HYPOTHESIS
def test_dp_equals_plain_recursive_reference(line: np.ndarray, eps: float) -> None:
    expected = reference_dp([tuple(p) for p in line.tolist()], eps)
    assert douglas_peucker(line, eps).tolist() == expected


def test_dp_with_zero_epsilon_keeps_every_vertex_off_the_chords() -> None:
    # Collinear middle vertex (1, 0) has distance 0 and goes even at eps = 0; the bump stays.
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
    assert douglas_peucker(line, 0.0).tolist() == [0, 2, 3, 4]


@pytest.mark.parametrize("eps", [-1.0, math.nan, math.inf])
def test_dp_rejects_a_negative_or_non_finite_epsilon(eps: float) -> None:
    with pytest.raises(InvalidParameter, match="epsilon"):
        douglas_peucker(np.array([[0.0, 0.0], [1.0, 1.0]]), eps)


def test_dp_rejects_coordinates_of_the_wrong_shape() -> None:
    with pytest.raises(InvalidParameter, match="shape"):
        douglas_peucker(np.zeros((4, 3)), 1.0)


# --- significance -----------------------------------------------------------------------------------------


def test_significance_of_a_single_bump_is_its_distance_to_the_chord() -> None:
    sig = significance(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]]))
    assert sig[0] == math.inf and sig[2] == math.inf
    assert sig[1] == pytest.approx(1.0, abs=1e-12)


def test_significance_of_a_child_is_capped_by_its_parent_split() -> None:
    # (5, 1) is 1 m off the chord y = 0 and splits first; (6, -0.9) is 8.5 / sqrt(26) = 1.667 m off the
    # sub-chord (5, 1)-(10, 0), but DP only looks there if (5, 1) was kept: its significance is 1, not 1.667.
    line = np.array([[0.0, 0.0], [5.0, 1.0], [6.0, -0.9], [10.0, 0.0]])
    sig = significance(line)
    assert sig[1] == pytest.approx(1.0, abs=1e-12)
    assert sig[2] == pytest.approx(1.0, abs=1e-12)
    assert douglas_peucker(line, 1.2).tolist() == [0, 3]
    assert douglas_peucker(line, 0.95).tolist() == [0, 1, 2, 3]


@given(random_lines(max_points=20), epsilons)
@HYPOTHESIS
def test_significance_above_epsilon_marks_exactly_the_reference_dp_vertices(
    line: np.ndarray, eps: float
) -> None:
    expected = reference_dp([tuple(p) for p in line.tolist()], eps)
    assert np.flatnonzero(significance(line) > eps).tolist() == expected


# --- rings ------------------------------------------------------------------------------------------------


def test_ring_anchors_of_a_rectangle_are_opposite_corners() -> None:
    rect = np.array([[0.0, 0.0], [1.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]])
    a, b = ring_anchors(rect)
    assert (a, b) == (0, 3)  # (0, 0) and (4, 2): the rectangle's diagonal


@given(random_rings(), st.floats(0.0, 1e6, allow_nan=False))
@HYPOTHESIS
def test_dp_of_a_ring_keeps_a_triangle_of_positive_area(ring: np.ndarray, eps: float) -> None:
    keep = douglas_peucker(ring, eps, closed=True)
    assert len(keep) >= 3
    assert shapely.Polygon(ring[keep]).area > 1.0


@given(random_rings(), epsilons)
@HYPOTHESIS
def test_dp_of_a_ring_keeps_dropped_vertices_within_epsilon_of_the_simplified_ring(
    ring: np.ndarray, eps: float
) -> None:
    keep = douglas_peucker(ring, eps, closed=True)
    simplified = shapely.LinearRing(ring[keep])
    for i in np.setdiff1d(np.arange(len(ring)), keep):
        assert shapely.Point(ring[i]).distance(simplified) <= eps + 1e-9


@given(random_rings(), epsilons, epsilons)
@HYPOTHESIS
def test_dp_of_a_ring_is_monotone_in_epsilon(ring: np.ndarray, eps_a: float, eps_b: float) -> None:
    small, large = sorted((eps_a, eps_b))
    assert set(douglas_peucker(ring, large, closed=True)) <= set(douglas_peucker(ring, small, closed=True))


def test_dp_of_a_circle_at_huge_epsilon_is_a_triangle_not_a_flat_line() -> None:
    angle = np.linspace(0.0, 2.0 * np.pi, 36, endpoint=False)
    circle = 100.0 * np.column_stack([np.cos(angle), np.sin(angle)])
    keep = douglas_peucker(circle, 1e9, closed=True)
    assert len(keep) == 3
    # The two anchors are a diameter apart; the third vertex is the farthest from it: 100 m off.
    area = shapely.Polygon(circle[keep]).area
    assert area == pytest.approx(0.5 * 200.0 * 100.0, rel=0.01)


def test_dp_of_a_three_vertex_ring_keeps_all_three() -> None:
    tri = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 1.0]])
    assert douglas_peucker(tri, 1e6, closed=True).tolist() == [0, 1, 2]


# --- count variant ----------------------------------------------------------------------------------------


@given(random_lines(grid=True), st.integers(-3, 40))
@HYPOTHESIS
def test_dp_count_of_a_line_returns_exactly_the_clipped_count(line: np.ndarray, n_keep: int) -> None:
    keep = douglas_peucker_count(line, n_keep)
    assert len(keep) == min(max(n_keep, 2), len(line))
    assert keep[0] == 0 and keep[-1] == len(line) - 1
    assert np.all(np.diff(keep) > 0)


@given(random_rings(), st.integers(-3, 40))
@HYPOTHESIS
def test_dp_count_of_a_ring_returns_exactly_the_clipped_count(ring: np.ndarray, n_keep: int) -> None:
    keep = douglas_peucker_count(ring, n_keep, closed=True)
    assert len(keep) == min(max(n_keep, 3), len(ring))
    assert len(np.unique(keep)) == len(keep)


@given(random_lines(min_points=3, max_points=20), epsilons)
@HYPOTHESIS
def test_dp_count_equals_reference_dp_with_the_same_number_of_vertices(line: np.ndarray, eps: float) -> None:
    expected = reference_dp([tuple(p) for p in line.tolist()], eps)
    assert douglas_peucker_count(line, len(expected)).tolist() == expected


@given(random_lines(min_points=3), st.integers(2, 24))
@HYPOTHESIS
def test_dp_count_results_are_nested_as_the_count_grows(line: np.ndarray, k: int) -> None:
    assert set(douglas_peucker_count(line, k)) <= set(douglas_peucker_count(line, k + 1))


def test_dp_count_is_deterministic_on_ties() -> None:
    # Two bumps of equal height: ties are broken by vertex order, the same way every call.
    line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
    first = douglas_peucker_count(line, 3)
    for _ in range(3):
        assert_array_equal(douglas_peucker_count(line, 3), first)


def numpy_ring_significance(xy: np.ndarray) -> np.ndarray:
    """A ring's significance stated with NumPy: split at two far apart vertices, DP of both halves, anchors and
    the most significant other vertex kept always."""
    n = len(xy)
    a = int(np.argmax(np.sum((xy - xy[0]) ** 2, axis=1)))  # the farthest from the first, then from that one
    b = int(np.argmax(np.sum((xy - xy[a]) ** 2, axis=1)))
    a, b = sorted((a, b if a != b else (a + 1) % n))
    sig = np.empty(n)
    sig[a : b + 1] = dp_significance(np.ascontiguousarray(xy[a : b + 1]))
    sig[np.concatenate([np.arange(b, n), np.arange(0, a + 1)])] = dp_significance(np.concatenate([xy[b:], xy[: a + 1]]))
    sig[a] = sig[b] = np.inf
    finite = np.flatnonzero(np.isfinite(sig))
    if len(finite):
        sig[finite[np.argmax(sig[finite])]] = np.inf
    return sig


@settings(deadline=None, max_examples=300)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(4, 120),
    repeats=st.lists(st.integers(0, 119), max_size=4),
    spiky=st.booleans(),
)
def test_ring_significance_is_the_numpy_rule_bit_for_bit(seed: int, n: int, repeats: list[int], spiky: bool) -> None:
    # Rings at UTM magnitudes, some with vertices at the same point (ties for the anchors and the triangle) or
    # on a coarse grid (equal distances, equal significances).
    rng = np.random.default_rng(seed)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
    xy = np.column_stack([np.cos(angle), np.sin(angle)]) * rng.uniform(50.0, 500.0, (n, 1))
    if spiky:
        xy = np.round(xy / 100.0) * 100.0
    xy += [650_000.0, 5_100_000.0]
    for i in repeats:
        xy[i % n] = xy[(i + 1) % n]
    assert np.array_equal(significance(xy, closed=True), numpy_ring_significance(xy))
