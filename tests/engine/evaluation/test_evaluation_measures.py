"""Hand-computed checks of the evaluation measures (paper eq. 11-13), jumps, groups and crossings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from engine.errors import InvalidParameter
from engine.evaluation.measures import (
    ErrorStats,
    crossing_pairs,
    largest_jump,
    linear_density,
    maav,
    pairwise_mean_abs,
    positional_errors,
    same_scale_groups,
)


def test_positional_errors_of_a_triangle_against_its_base() -> None:
    initial = np.array([[0.0, 0.0], [5.0, 3.0], [10.0, 0.0]])
    simplified = np.array([[0.0, 0.0], [10.0, 0.0]])
    errors = positional_errors(initial, simplified, closed=False)
    assert_allclose(errors, [0.0, 3.0, 0.0], atol=1e-12)
    stats = ErrorStats.of(errors)
    # mean 1, population std sqrt(((0-1)^2 + (3-1)^2 + (0-1)^2) / 3) = sqrt(2), max 3
    assert stats.mean_m == pytest.approx(1.0)
    assert stats.std_m == pytest.approx(math.sqrt(2.0))
    assert stats.max_m == pytest.approx(3.0)


def test_positional_error_uses_the_nearest_segment_and_the_ring_closing_segment() -> None:
    # Square ring simplified to a triangle: the dropped corner (0, 10) lies 10 / sqrt(2) from the diagonal
    # (10, 10)-(0, 0), which only exists as the ring's closing segment.
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    triangle = square[:3]
    errors = positional_errors(square, triangle, closed=True)
    assert_allclose(errors, [0.0, 0.0, 0.0, 10.0 / math.sqrt(2.0)], atol=1e-12)
    # Open, the corner's nearest piece is the point (10, 10): distance 10.
    assert positional_errors(square, triangle, closed=False)[3] == pytest.approx(10.0)


def test_linear_density_of_a_segment_and_a_square() -> None:
    # Segment of 10 m, buffer 1 m: area 2 * 10 * 1 + pi * 1^2 (round caps, here polygonal within 0.1 %).
    seg = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert linear_density(seg, False, 1.0) == pytest.approx(10.0 / (20.0 + math.pi), rel=1e-3)
    # Square ring of side 10, buffer 1: outer rounded square 12^2 - 4 + pi (corners), minus inner 8^2.
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    area = (144.0 - 4.0 + math.pi) - 64.0
    assert linear_density(square, True, 1.0) == pytest.approx(40.0 / area, rel=1e-3)


def test_linear_density_without_width_is_nan_and_negative_width_raises() -> None:
    seg = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert math.isnan(linear_density(seg, False, 0.0))
    with pytest.raises(InvalidParameter):
        linear_density(seg, False, -1.0)


def test_maav_by_hand() -> None:
    # Two groups of (CCSM, DP, WM) similarities.
    sims = np.array([[0.950, 0.951, 0.949], [0.900, 0.900, 0.902]])
    sd = pairwise_mean_abs(sims)
    # |CCSM-DP|: (0.001 + 0) / 2; |CCSM-WM|: (0.001 + 0.002) / 2; |DP-WM|: (0.002 + 0.002) / 2
    assert sd[0, 1] == pytest.approx(0.0005)
    assert sd[0, 2] == pytest.approx(0.0015)
    assert sd[1, 2] == pytest.approx(0.002)
    assert maav(sims) == pytest.approx(0.002)
    assert maav(np.array([[0.5, 0.5, 0.5]])) == 0.0
    with pytest.raises(InvalidParameter):
        maav(np.zeros((0, 3)))


def test_same_scale_groups_pick_levels_within_the_window() -> None:
    ccsm = np.array([1.0, 0.999, 0.990, 0.980, 0.970])
    dp = np.array([1.0, 1.0, 0.9905, 0.9905, 0.900])
    wm = np.array([1.0, 0.9995, 0.9890, 0.960, 0.960])
    groups = same_scale_groups([ccsm, dp, wm])
    # Only Sim ~ 0.99 has a member of every method within 0.002 (and below 0.998).
    assert groups == [(2, 2, 2)]
    for g in groups:
        vals = [ccsm[g[0]], dp[g[1]], wm[g[2]]]
        assert max(vals) - min(vals) <= 0.002 + 1e-12


def test_largest_jump() -> None:
    assert largest_jump(np.array([1.0, 0.99, 0.9, 0.89])) == pytest.approx(0.09)
    assert largest_jump(np.array([1.0])) == 0.0


def test_crossing_pairs_counts_meeting_and_crossing_separately() -> None:
    a = np.array([[0.0, 0.0], [2.0, 2.0]])
    b = np.array([[0.0, 2.0], [2.0, 0.0]])  # crosses a
    c = np.array([[2.0, 2.0], [3.0, 5.0]])  # touches a at an end point only
    d = np.array([[10.0, 10.0], [11.0, 10.0], [11.0, 11.0]])  # a ring far away
    hit, cross = crossing_pairs([a, b, c, d], [False, False, False, True])
    assert (hit, cross) == (2, 1)
    assert crossing_pairs([a], [False]) == (0, 0)
