"""Tests of engine.geom.kernels against plain-Python twins: DP significance and the banded discrete Fréchet."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_frechet import reference_frechet

from engine.geom.kernels import discrete_frechet, dp_significance

HYPOTHESIS = settings(deadline=None, max_examples=80)


def reference_significance(xy: np.ndarray) -> list[float]:
    """Largest tolerance at which plain recursive DP keeps each vertex (inf for the ends), in any dimension."""
    n = len(xy)
    sig = [0.0] * n
    sig[0] = sig[-1] = math.inf

    def recurse(first: int, last: int, cap: float) -> None:
        if last - first < 2:
            return
        a, b = xy[first], xy[last]
        best, best_i = -1.0, first + 1
        for i in range(first + 1, last):
            seg = b - a
            seg2 = float(seg @ seg)
            u = min(1.0, max(0.0, float((xy[i] - a) @ seg) / seg2)) if seg2 > 0 else 0.0
            d = float(np.sqrt(np.sum((xy[i] - a - u * seg) ** 2)))
            if d > best:
                best, best_i = d, i
        s = min(best, cap)
        sig[best_i] = s
        recurse(first, best_i, s)
        recurse(best_i, last, s)

    recurse(0, n - 1, math.inf)
    return sig


@st.composite
def point_sequences(draw: st.DrawFn, max_points: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Two seeded point sequences; on a small grid they have many equal distances."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(1, max_points))
    m = draw(st.integers(1, max_points))
    grid = draw(st.booleans())
    rng = np.random.default_rng(seed)
    if grid:
        return rng.integers(0, 5, (n, 2)).astype(float), rng.integers(0, 5, (m, 2)).astype(float)
    return rng.normal(0.0, 10.0, (n, 2)), rng.normal(0.0, 10.0, (m, 2))


@given(point_sequences())
@HYPOTHESIS
def test_frechet_kernel_without_bound_equals_the_reference(pq: tuple[np.ndarray, np.ndarray]) -> None:
    p, q = pq
    assert discrete_frechet(p, q, math.inf) == pytest.approx(reference_frechet(p, q), abs=1e-9)


@given(point_sequences(), st.floats(1.0 + 1e-9, 5.0))
@HYPOTHESIS
def test_frechet_kernel_with_any_loose_bound_equals_the_reference(
    pq: tuple[np.ndarray, np.ndarray], factor: float
) -> None:
    p, q = pq
    expected = reference_frechet(p, q)
    assert discrete_frechet(p, q, expected * factor + 1e-9) == pytest.approx(expected, abs=1e-9)


@given(point_sequences(), st.floats(0.0, 0.99))
@HYPOTHESIS
def test_frechet_kernel_returns_inf_when_the_bound_is_below_the_distance(
    pq: tuple[np.ndarray, np.ndarray], factor: float
) -> None:
    p, q = pq
    expected = reference_frechet(p, q)
    if expected == 0.0:
        return
    assert discrete_frechet(p, q, expected * factor) == math.inf


def test_frechet_kernel_accepts_the_exact_distance_as_its_bound() -> None:
    p = np.array([[0.0, 0.0]])
    q = np.array([[2.0, 3.0]])
    assert discrete_frechet(p, q, math.sqrt(13.0)) == pytest.approx(math.sqrt(13.0), abs=1e-12)


def test_frechet_kernel_on_a_hand_worked_pair() -> None:
    # p walks (0,0) -> (2,0); q walks (0,1) -> (1,3) -> (2,1): the leash must reach (1,3) from p's points,
    # the nearest of which is (0,0) or (2,0) at sqrt(1 + 9) = sqrt(10).
    p = np.array([[0.0, 0.0], [2.0, 0.0]])
    q = np.array([[0.0, 1.0], [1.0, 3.0], [2.0, 1.0]])
    assert discrete_frechet(p, q, math.inf) == pytest.approx(math.sqrt(10.0), abs=1e-12)


@given(st.integers(0, 2**32 - 1), st.integers(2, 30))
@settings(deadline=None, max_examples=60)
def test_dp_significance_equals_the_recursive_reference(seed: int, n: int) -> None:
    xy = np.cumsum(np.random.default_rng(seed).normal(0.0, 10.0, (n, 2)), axis=0)
    np.testing.assert_allclose(dp_significance(xy), reference_significance(xy), rtol=1e-12, atol=1e-12)


@given(st.integers(0, 2**32 - 1), st.integers(2, 30))
@settings(deadline=None, max_examples=60)
def test_dp_significance_of_two_coordinate_pairs_is_that_of_the_4d_line(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(0.0, 10.0, (n, 2)), axis=0)
    zw = np.cumsum(rng.normal(0.0, 30.0, (n, 2)), axis=0)
    expected = reference_significance(np.concatenate([xy, zw], axis=1))
    np.testing.assert_allclose(dp_significance(xy, zw), expected, rtol=1e-12, atol=1e-12)


def test_dp_significance_of_a_two_point_line_is_inf_at_both_ends() -> None:
    assert dp_significance(np.array([[0.0, 0.0], [1.0, 1.0]])).tolist() == [math.inf, math.inf]


def test_dp_significance_measures_a_vertex_beyond_the_chord_end_to_the_end_point() -> None:
    # (5, 0) lies on the chord's line but 3 m beyond its end (2, 0): segment distance 3, line distance 0.
    sig = dp_significance(np.array([[0.0, 0.0], [5.0, 0.0], [2.0, 0.0]]))
    assert sig[1] == pytest.approx(3.0, abs=1e-12)
