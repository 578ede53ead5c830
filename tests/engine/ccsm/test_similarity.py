"""Tests of engine.ccsm.similarity: exact discrete Fréchet and the paper's Sim = 1 - dF / Length (eq. 9)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_frechet import reference_frechet
from scipy.spatial.distance import cdist

from engine.ccsm.ccs import build_ccs
from engine.ccsm.similarity import (
    SimilarityReference,
    discrete_frechet_distance,
    resample_count,
    similarity,
)
from engine.errors import InvalidParameter
from engine.evaluation.levels import eval_params
from engine.evaluation.pipeline import evaluate_contour
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.params import BuildParams
from engine.types import Contour

HYPOTHESIS = settings(deadline=None, max_examples=60)


@st.composite
def curve_pairs(draw: st.DrawFn, max_points: int = 14) -> tuple[np.ndarray, np.ndarray]:
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(1, max_points))
    m = draw(st.integers(1, max_points))
    rng = np.random.default_rng(seed)
    p = np.cumsum(rng.normal(0.0, 5.0, (n, 2)), axis=0)
    q = np.cumsum(rng.normal(0.0, 5.0, (m, 2)), axis=0) + rng.normal(0.0, 3.0, 2)
    return p, q


@given(curve_pairs())
@HYPOTHESIS
def test_discrete_frechet_equals_the_quadratic_reference(pq: tuple[np.ndarray, np.ndarray]) -> None:
    p, q = pq
    assert discrete_frechet_distance(p, q) == pytest.approx(reference_frechet(p, q), abs=1e-9)


@given(curve_pairs())
@HYPOTHESIS
def test_discrete_frechet_is_symmetric(pq: tuple[np.ndarray, np.ndarray]) -> None:
    p, q = pq
    assert discrete_frechet_distance(p, q) == pytest.approx(discrete_frechet_distance(q, p), abs=1e-9)


@given(curve_pairs())
@HYPOTHESIS
def test_discrete_frechet_of_a_curve_with_itself_is_zero(pq: tuple[np.ndarray, np.ndarray]) -> None:
    p, _ = pq
    assert discrete_frechet_distance(p, p.copy()) == 0.0


@given(curve_pairs())
@HYPOTHESIS
def test_discrete_frechet_is_at_least_the_discrete_hausdorff_distance(
    pq: tuple[np.ndarray, np.ndarray],
) -> None:
    p, q = pq
    d = cdist(p, q)
    hausdorff = max(d.min(axis=1).max(), d.min(axis=0).max())
    assert discrete_frechet_distance(p, q) >= hausdorff - 1e-9


@given(curve_pairs(), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6))
@HYPOTHESIS
def test_discrete_frechet_is_invariant_to_translating_both_curves(
    pq: tuple[np.ndarray, np.ndarray], dx: float, dy: float
) -> None:
    p, q = pq
    shift = np.array([dx, dy])
    expected = discrete_frechet_distance(p, q)
    assert discrete_frechet_distance(p + shift, q + shift) == pytest.approx(expected, rel=1e-9, abs=1e-6)


def test_discrete_frechet_of_parallel_segments_is_their_offset() -> None:
    p = np.array([[0.0, 0.0], [1.0, 0.0]])
    q = np.array([[0.0, 1.0], [1.0, 1.0]])
    assert discrete_frechet_distance(p, q) == pytest.approx(1.0, abs=1e-12)


def test_discrete_frechet_rejects_an_empty_sequence() -> None:
    with pytest.raises(InvalidParameter):
        discrete_frechet_distance(np.zeros((0, 2)), np.zeros((3, 2)))


def test_discrete_frechet_on_long_utm_curves_matches_shapely() -> None:
    # 400 x 400 points at UTM-sized coordinates: exercises the band and the bound's rounding margin.
    rng = np.random.default_rng(5)
    p = np.array([750_000.0, 4_060_000.0]) + np.cumsum(rng.normal(0.0, 5.0, (400, 2)), axis=0)
    q = p + rng.normal(0.0, 2.0, p.shape)
    expected = shapely.frechet_distance(shapely.LineString(p), shapely.LineString(q), densify=None)
    # shapely's (undensified) Fréchet is the discrete one over the vertices.
    assert discrete_frechet_distance(p, q) == pytest.approx(expected, rel=1e-9)


# --- Sim ----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("closed", [False, True])
def test_similarity_of_a_curve_with_itself_is_one(closed: bool) -> None:
    angle = np.linspace(0.0, 2.0 * np.pi, 50, endpoint=False)
    coords = np.column_stack([300.0 * np.cos(angle), 200.0 * np.sin(angle)])
    assert similarity(coords, coords.copy(), closed) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("shift", [(3.0, 4.0), (0.0, 12.5), (-7.0, 1.0)])
def test_similarity_of_a_shifted_open_line_is_one_minus_shift_over_length(shift: tuple[float, float]) -> None:
    rng = np.random.default_rng(2)
    line = np.cumsum(rng.normal(0.0, 20.0, (40, 2)), axis=0)
    length = float(np.hypot(*np.diff(line, axis=0).T).sum())
    moved = line + np.array(shift)
    expected = 1.0 - math.hypot(*shift) / length
    assert similarity(line, moved, closed=False) == pytest.approx(expected, abs=1e-9)


def test_similarity_of_a_shifted_ring_is_one_minus_shift_over_perimeter() -> None:
    square = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]])
    assert similarity(square, square + [6.0, 8.0], closed=True) == pytest.approx(1.0 - 10.0 / 400.0, abs=1e-9)


def test_improved_frechet_is_the_distance_after_equal_count_resampling() -> None:
    # L0 = straight 100 m; L = the same segment with an extra middle vertex: identical after resampling.
    l0 = np.array([[0.0, 0.0], [100.0, 0.0]])
    other = np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]])
    assert SimilarityReference.of(l0, closed=False, spacing_m=10.0).frechet(other) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(
    ("length", "spacing", "floor", "cap", "expected"),
    [
        (100.0, 10.0, 2, 2000, 11),
        (0.0, 10.0, 0, 2000, 2),
        (1e6, 10.0, 256, 2000, 2000),
        (104.0, 10.0, 2, 2000, 11),
        (100.0, 10.0, 256, 2000, 256),
        (5000.0, 10.0, 256, 2000, 501),
    ],
)
def test_resample_count_is_one_per_spacing_between_the_floor_and_the_cap(
    length: float, spacing: float, floor: int, cap: int, expected: int
) -> None:
    assert resample_count(length, spacing, cap, floor) == expected


@pytest.fixture(scope="module")
def sample_by_id() -> dict[str, Contour]:
    """The bundled sample's contours by id, read once for the tests that need real contours."""
    return {str(c.id): c for c in read_source(sample_contours_path()).contours}


@pytest.mark.parametrize("contour_id", ["560:49", "260:6", "740:12"])
def test_short_sample_contours_have_a_falling_ccsm_similarity(
    contour_id: str, sample_by_id: dict[str, Contour]
) -> None:
    # Three short contours of the sample (113 m, 432 m, 1.3 km) whose Sim rose between neighbouring levels
    # when they were resampled at one point per 10 m only (12, 44, 129 samples): sampling wobble, not shape.
    result = evaluate_contour(0, sample_by_id[contour_id], 100, eval_params("extreme", 50_000, 500_000))
    ccsm = result.sims[0]
    assert np.all(np.diff(ccsm) <= 1e-9), np.diff(ccsm).max()


def test_similarity_reference_rejects_a_zero_length_contour() -> None:
    with pytest.raises(InvalidParameter):
        SimilarityReference.of(np.array([[1.0, 1.0], [1.0, 1.0]]), closed=False)


def slice_by_slice(reference: SimilarityReference, base: np.ndarray, top: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """Sim of each slice measured on its own, a ring's slice without its repeated last point (eq. 9)."""
    slices = [(1.0 - t) * base + t * top for t in ts]
    return np.array([reference.similarity(s[:-1] if reference.closed else s) for s in slices])


@pytest.mark.parametrize("contour_id", ["560:49", "260:6", "740:12", "260:2", "360:107", "580:52"])
def test_slice_similarities_equal_the_similarity_of_each_slice(
    contour_id: str, sample_by_id: dict[str, Contour]
) -> None:
    contour = sample_by_id[contour_id]
    ccs = build_ccs(contour, BuildParams())
    reference = SimilarityReference.of(contour.coords, contour.closed)
    ts = np.linspace(0.0, 1.0, 11)
    np.testing.assert_array_equal(
        reference.slice_similarities(ccs.base, ccs.top, ts), slice_by_slice(reference, ccs.base, ccs.top, ts)
    )


def test_slice_similarities_of_rows_whose_slice_folds_onto_itself() -> None:
    # Two points swap places between the rows: at t = 0.5 they coincide, a zero-length segment in the slice.
    base = np.array([[0.0, 0.0], [40.0, 5.0], [80.0, 0.0], [120.0, 0.0], [160.0, 3.0], [200.0, 0.0]])
    top = base.copy()
    top[2], top[3] = base[3], base[2]
    reference = SimilarityReference.of(base, closed=False)
    ts = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    sims = reference.slice_similarities(base, top, ts)
    np.testing.assert_array_equal(sims, slice_by_slice(reference, base, top, ts))
    assert sims[0] == pytest.approx(1.0, abs=1e-12)
    assert sims[2] < sims[0]


def test_slice_similarities_need_a_rings_rows_closed() -> None:
    angle = np.linspace(0.0, 2 * np.pi, 30, endpoint=False)
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) * 200.0
    reference = SimilarityReference.of(ring, closed=True)
    with pytest.raises(InvalidParameter):
        reference.slice_similarities(ring, ring * 0.9, np.array([0.0, 1.0]))
