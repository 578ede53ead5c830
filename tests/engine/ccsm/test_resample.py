"""Tests of engine.ccsm.resample: correspondence samples of L0 and Ln (paper section 2.1 (2))."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from engine.ccsm.resample import Correspondence, correspond, densify_path
from engine.errors import InvalidContour, InvalidParameter
from engine.geom.douglas_peucker import douglas_peucker
from engine.geom.polyline import closed_path, segment_lengths

HYPOTHESIS = settings(deadline=None, max_examples=50)


@st.composite
def line_with_characteristic(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float]:
    """A seeded open line (or a ring as a closed path), DP characteristic points, and a spacing."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(3, 40))
    ring = draw(st.booleans())
    eps = draw(st.floats(0.0, 80.0))
    spacing = draw(st.floats(2.0, 60.0))
    rng = np.random.default_rng(seed)
    if ring:
        angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, n + 1))[:n]
        xy = np.column_stack([np.cos(angle), np.sin(angle)]) * rng.uniform(100.0, 200.0, (n, 1))
        keep = douglas_peucker(xy, eps, closed=True)
        xy = np.roll(xy, -int(keep[0]), axis=0)
        keep = np.append(keep - keep[0], n)
        path = closed_path(xy)
    else:
        path = np.cumsum(rng.normal(0.0, 30.0, (n, 2)), axis=0)
        keep = douglas_peucker(path, eps)
    return path + [750_000.0, 4_060_000.0], keep, spacing


# -- properties of every correspondence, each checked on the same generated lines -----------------------------


def keeps_every_vertex_of_l0_in_order(path: np.ndarray, keep: np.ndarray, spacing: float, corr: Correspondence) -> None:
    position = 0
    for vertex in path:  # each vertex appears, in order, among the samples
        hits = np.flatnonzero(np.all(corr.initial[position:] == vertex, axis=1))
        assert len(hits) > 0
        position += int(hits[0]) + 1


def characteristic_samples_coincide_on_both_sides(
    path: np.ndarray, keep: np.ndarray, spacing: float, corr: Correspondence
) -> None:
    assert len(corr.characteristic) == len(keep)
    assert_allclose(corr.initial[corr.characteristic], path[keep], rtol=0, atol=1e-9)
    assert_allclose(corr.target[corr.characteristic], path[keep], rtol=0, atol=1e-6)


def target_samples_lie_on_the_segments_between_characteristic_points(
    path: np.ndarray, keep: np.ndarray, spacing: float, corr: Correspondence
) -> None:
    for piece in range(len(keep) - 1):
        lo, hi = corr.characteristic[piece], corr.characteristic[piece + 1]
        segment = shapely.LineString(path[[keep[piece], keep[piece + 1]]])
        for point in corr.target[lo : hi + 1]:
            assert segment.distance(shapely.Point(point)) <= 1e-6


def equal_counts_and_gaps_within_spacing(
    path: np.ndarray, keep: np.ndarray, spacing: float, corr: Correspondence
) -> None:
    assert corr.initial.shape == corr.target.shape
    gaps = np.hypot(*np.diff(corr.initial, axis=0).T)
    assert gaps.max() <= spacing * (1 + 1e-9)


def target_advances_in_proportion_to_arc_length_on_l0(
    path: np.ndarray, keep: np.ndarray, spacing: float, corr: Correspondence
) -> None:
    for piece in range(len(keep) - 1):
        lo, hi = corr.characteristic[piece], corr.characteristic[piece + 1]
        l0 = np.hypot(*np.diff(corr.initial[lo : hi + 1], axis=0).T)
        ln = np.hypot(*np.diff(corr.target[lo : hi + 1], axis=0).T)
        chord = np.hypot(*(path[keep[piece + 1]] - path[keep[piece]]))
        assert_allclose(ln, l0 / l0.sum() * chord, rtol=1e-6, atol=1e-6)


CORRESPONDENCE_PROPERTIES = [
    keeps_every_vertex_of_l0_in_order,
    characteristic_samples_coincide_on_both_sides,
    target_samples_lie_on_the_segments_between_characteristic_points,
    equal_counts_and_gaps_within_spacing,
    target_advances_in_proportion_to_arc_length_on_l0,
]


@pytest.mark.parametrize("holds", CORRESPONDENCE_PROPERTIES, ids=lambda holds: holds.__name__)
@given(line_with_characteristic())
@HYPOTHESIS
def test_correspond(
    holds: Callable[[np.ndarray, np.ndarray, float, Correspondence], None],
    case: tuple[np.ndarray, np.ndarray, float],
) -> None:
    path, keep, spacing = case
    holds(path, keep, spacing, correspond(path, keep, spacing))


def test_densify_path_splits_a_long_edge_into_equal_pieces() -> None:
    points, vertex_index = densify_path(np.array([[0.0, 0.0], [10.0, 0.0], [11.0, 0.0]]), 4.0)
    # 10 m at <= 4 m spacing: 3 pieces of 3.33 m; the 1 m edge stays whole.
    assert_allclose(points[:, 0], [0.0, 10 / 3, 20 / 3, 10.0, 11.0], atol=1e-12)
    assert vertex_index.tolist() == [0, 3, 4]


@pytest.mark.parametrize("spacing", [0.0, -1.0, float("nan"), float("inf")])
def test_correspond_rejects_a_non_positive_or_non_finite_spacing(spacing: float) -> None:
    with pytest.raises(InvalidParameter):
        correspond(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]]), np.array([0, 2]), spacing)


@pytest.mark.parametrize("keep", [[0, 1], [1, 2], [0], [0, 2, 1, 2]])
def test_correspond_rejects_characteristic_points_missing_an_end_or_unordered(keep: list[int]) -> None:
    with pytest.raises(InvalidContour):
        correspond(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]]), np.array(keep), 1.0)


# -- the compiled kernels against the NumPy arithmetic they replaced, to the last bit --------------------------


def numpy_densify_path(path: np.ndarray, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """densify_path as whole-array NumPy: the rule stated array by array."""
    edges = segment_lengths(path)
    pieces = np.maximum(np.ceil(edges / spacing_m).astype(np.intp), 1)
    starts = np.concatenate([[0], np.cumsum(pieces)])
    edge_of = np.repeat(np.arange(len(edges)), pieces)
    frac = (np.arange(int(starts[-1])) - starts[edge_of]) / pieces[edge_of]
    a, b = path[edge_of], path[edge_of + 1]
    points = np.concatenate([a + (b - a) * frac[:, None], path[-1:]])
    return points, starts.astype(np.intp)


def numpy_correspond(path: np.ndarray, char: np.ndarray, spacing_m: float) -> tuple[np.ndarray, ...]:
    """correspond as whole-array NumPy: (initial, target, characteristic), or InvalidContour for a flat piece."""
    initial, vertex_pos = numpy_densify_path(path, spacing_m)
    arclen = np.concatenate([[0.0], np.cumsum(segment_lengths(initial))])
    char_pos = vertex_pos[char]
    piece = np.minimum(np.searchsorted(char_pos, np.arange(len(initial)), side="right") - 1, len(char) - 2)
    s0, s1 = arclen[char_pos[piece]], arclen[char_pos[piece + 1]]
    if np.any(s1 - s0 <= 0):
        raise InvalidContour("a characteristic sub-polyline has zero length")
    a, b = path[char[piece]], path[char[piece + 1]]
    return initial, a + (b - a) * ((arclen - s0) / (s1 - s0))[:, None], char_pos


@st.composite
def line_with_repeats(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float]:
    """A line_with_characteristic whose vertices may be repeated (edges of no length, pieces of no length),
    with any ascending characteristic points that hold both ends."""
    path, keep, spacing = draw(line_with_characteristic())
    repeat = draw(st.lists(st.integers(0, len(path) - 1), max_size=3))
    path = np.insert(path, repeat, path[repeat], axis=0)
    inner = draw(st.sets(st.integers(1, len(path) - 2), max_size=len(path) - 2))
    if draw(st.booleans()):  # a DP-like choice, shifted past the repeats; or any drawn one
        inner = set(np.searchsorted(np.sort(repeat), keep[1:-1], side="right") + keep[1:-1])
    return path, np.array(sorted({0, len(path) - 1} | inner)), spacing


@given(line_with_repeats())
@settings(deadline=None, max_examples=300)
def test_correspond_gives_the_numpy_arithmetic_bit_for_bit(case: tuple[np.ndarray, np.ndarray, float]) -> None:
    path, keep, spacing = case
    try:
        expected = numpy_correspond(path, keep, spacing)
    except InvalidContour:
        with pytest.raises(InvalidContour, match="zero length"):
            correspond(path, keep, spacing)
        return
    corr = correspond(path, keep, spacing)
    for got, want in zip((corr.initial, corr.target, corr.characteristic), expected, strict=True):
        assert got.shape == want.shape
        assert np.array_equal(got, want)
    points, vertex_index = densify_path(path, spacing)
    want_points, want_index = numpy_densify_path(path, spacing)
    assert np.array_equal(points, want_points)
    assert np.array_equal(vertex_index, want_index)


def test_densify_path_refuses_an_empty_path() -> None:
    with pytest.raises(InvalidContour, match="at least one vertex"):
        densify_path(np.zeros((0, 2)), 1.0)
