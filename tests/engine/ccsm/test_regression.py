"""Tests of engine.ccsm.regression: the exponential model, scale -> t tables and the per-group fit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from engine.ccsm.regression import (
    GroupModel,
    ScaleModel,
    assign_groups,
    exponential_model,
    fit_scale_model,
    t_for_scale,
)
from engine.params import BuildParams
from engine.types import Contour

HYPOTHESIS = settings(deadline=None, max_examples=60)
S0, S1 = 50_000.0, 500_000.0
LADDER = np.geomspace(S0, S1, 33)


def log_model(groups: tuple[GroupModel, ...] = ()) -> ScaleModel:
    return ScaleModel(S0, S1, LADDER, groups)


def exp_group(a: float, b: float, c: float, d: float) -> GroupModel:
    return GroupModel((a, b, c, d), reference_id=0, scales=np.zeros(0), similarities=np.zeros(0))


@st.composite
def sim_tables(draw: st.DrawFn, monotone: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A seeded Sim(t) table: 1 at t = 0, then falling (or, unless ``monotone``, wobbling) downwards."""
    seed = draw(st.integers(0, 2**32 - 1))
    k = draw(st.integers(2, 21))
    rng = np.random.default_rng(seed)
    drops = rng.exponential(0.01, k - 1) * (rng.random(k - 1) < 0.8)
    sim = 1.0 - np.concatenate([[0.0], np.cumsum(drops)])
    if not monotone:
        sim = sim + rng.normal(0.0, 0.003, k) * (np.arange(k) > 0)
    return np.linspace(0.0, 1.0, k), sim


# --- the model --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("x", "coef", "expected"),
    [
        (0.0, (1.0, 2.0, 3.0, 4.0), 4.0),
        (1.0, (1.0, 0.0, 0.0, 5.0), 1.0),
        (2.0, (0.5, -1.0, 0.25, -0.5), 0.5 * math.exp(-2.0) + 0.25 * math.exp(-1.0)),
        (10.0, (0.98, -0.01, 0.02, -0.2), 0.98 * math.exp(-0.1) + 0.02 * math.exp(-2.0)),
    ],
)
def test_exponential_model_is_a_sum_of_two_exponentials(
    x: float, coef: tuple[float, ...], expected: float
) -> None:
    assert float(exponential_model(np.array([x]), *coef)[0]) == pytest.approx(expected, rel=1e-12)


# --- t tables ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("groups", [(), (exp_group(0.98, -0.01, 0.02, -0.3),)])
@given(table=sim_tables(monotone=True))
@HYPOTHESIS
def test_t_table_is_non_decreasing_from_zero_to_one(
    groups: tuple[GroupModel, ...], table: tuple[np.ndarray, np.ndarray]
) -> None:
    sim_t, sim = table
    t = log_model(groups).t_table(0, sim_t, sim)
    assert t.shape == LADDER.shape
    assert t[0] == 0.0 and t[-1] == 1.0
    assert np.all(np.diff(t) >= 0.0)
    assert np.all((t >= 0.0) & (t <= 1.0))


@given(sim_tables(monotone=False))
@HYPOTHESIS
def test_t_table_stays_monotone_when_the_measured_sim_wobbles(table: tuple[np.ndarray, np.ndarray]) -> None:
    sim_t, sim = table
    t = log_model().t_table(0, sim_t, sim)
    assert t[0] == 0.0 and t[-1] == 1.0
    assert np.all(np.diff(t) >= 0.0)


def test_log_mapping_with_a_linear_sim_table_gives_t_linear_in_log_scale() -> None:
    sim_t = np.linspace(0.0, 1.0, 11)
    sim = 1.0 - 0.05 * sim_t  # loss share == t, so t must equal the log share of the scale
    expected = np.log(LADDER / S0) / np.log(S1 / S0)
    assert_allclose(log_model().t_table(0, sim_t, sim), expected, rtol=0, atol=1e-12)


def test_t_table_of_a_flat_sim_table_follows_the_log_share() -> None:
    sim_t = np.linspace(0.0, 1.0, 5)
    expected = np.log(LADDER / S0) / np.log(S1 / S0)
    assert_allclose(log_model().t_table(0, sim_t, np.ones(5)), expected, rtol=0, atol=1e-12)


def test_loss_share_of_an_exponential_group_is_its_normalised_similarity_loss() -> None:
    a, b, c, d = 0.9, -0.01, 0.1, -0.4
    model = log_model((exp_group(a, b, c, d),))
    scales = np.array([S0, 120_000.0, 300_000.0, S1])
    x = scales / S0

    def f(v: np.ndarray) -> np.ndarray:
        return a * np.exp(b * v) + c * np.exp(d * v)

    expected = (f(np.array(1.0)) - f(x)) / (f(np.array(1.0)) - f(np.array(10.0)))
    assert_allclose(model.loss_share(0, scales), expected, rtol=1e-12, atol=1e-12)


def test_unknown_group_falls_back_to_the_log_share() -> None:
    model = log_model((exp_group(0.9, -0.01, 0.1, -0.4),))
    scales = np.array([S0, 158_113.883, S1])
    assert_allclose(model.loss_share(7, scales), [0.0, 0.5, 1.0], atol=1e-9)


# --- t_for_scale ------------------------------------------------------------------------------------------


@given(sim_tables(), st.floats(1_000.0, 5e6), st.floats(1_000.0, 5e6))
@HYPOTHESIS
def test_t_for_scale_is_monotone_in_scale(
    table: tuple[np.ndarray, np.ndarray], s_a: float, s_b: float
) -> None:
    t_table = log_model().t_table(0, *table)
    small, large = sorted((s_a, s_b))
    assert t_for_scale(LADDER, t_table, small) <= t_for_scale(LADDER, t_table, large)


@pytest.mark.parametrize(
    ("scale", "expected"), [(S0, 0.0), (10_000.0, 0.0), (1.0, 0.0), (S1, 1.0), (2e6, 1.0)]
)
def test_t_for_scale_is_zero_at_or_below_source_and_one_at_or_above_target(
    scale: float, expected: float
) -> None:
    t_table = np.log(LADDER / S0) / np.log(S1 / S0)
    assert t_for_scale(LADDER, t_table, scale) == expected


def test_t_for_scale_interpolates_in_log_scale() -> None:
    t_table = np.log(LADDER / S0) / np.log(S1 / S0)
    middle = math.sqrt(S0 * S1)  # halfway in log scale
    assert t_for_scale(LADDER, t_table, middle) == pytest.approx(0.5, abs=1e-9)


# --- fitting ----------------------------------------------------------------------------------------------


def synthetic_contours(n: int = 30) -> list[Contour]:
    """Seeded rings and lines of several sizes and wiggliness, spread apart."""
    rng = np.random.default_rng(21)
    out = []
    for i in range(n):
        size = rng.choice([60.0, 300.0, 1500.0])
        m = 80
        if i % 2:
            angle = np.linspace(0.0, 2.0 * np.pi, m, endpoint=False)
            radial = size * (1.0 + rng.uniform(0.0, 0.1) * rng.standard_normal(m))
            xy = np.column_stack([radial * np.cos(angle), radial * np.sin(angle)])
        else:
            xy = np.column_stack([np.linspace(0.0, 2 * size, m), np.cumsum(rng.normal(0.0, size / 20, m))])
        out.append(Contour(i, 0.0, xy + [5000.0 * i, 0.0], closed=bool(i % 2)))
    return out


def test_fit_scale_model_returns_one_group_model_per_group_and_labels_in_range() -> None:
    contours = synthetic_contours()
    params = BuildParams(groups=4)
    model, labels = fit_scale_model(contours, params)
    assert len(model.groups) == 4
    assert labels.shape == (len(contours),)
    assert labels.min() >= 0 and labels.max() < 4
    assert (model.source_scale, model.target_scale) == (S0, S1)
    assert_allclose(model.ladder, np.geomspace(S0, S1, params.scale_levels), rtol=1e-12)


def test_fitted_group_models_fall_from_source_to_target() -> None:
    model, _ = fit_scale_model(synthetic_contours(), BuildParams(groups=3))
    for g, group in enumerate(model.groups):
        share = model.loss_share(g, model.ladder)
        assert share[0] == pytest.approx(0.0, abs=1e-12) and share[-1] == pytest.approx(1.0, abs=1e-12)
        assert np.all(np.diff(share) >= -1e-12)
        if group.coefficients is not None:
            assert len(group.similarities) == len(group.scales)


def test_log_scale_mapping_fits_no_groups() -> None:
    contours = synthetic_contours(6)
    model, labels = fit_scale_model(contours, BuildParams(scale_mapping="log"))
    assert model.groups == ()
    assert labels.tolist() == [0] * 6
    expected = np.log(model.ladder / S0) / np.log(S1 / S0)
    assert_allclose(model.loss_share(0, model.ladder), expected, rtol=0, atol=1e-12)


def test_fewer_contours_than_groups_gives_one_group_per_contour() -> None:
    contours = synthetic_contours(2)
    labels, references = assign_groups(contours, 5)
    assert len(references) == 2
    assert sorted(labels.tolist()) == [0, 1]


def test_fit_scale_model_of_no_contours_is_the_log_mapping() -> None:
    model, labels = fit_scale_model([], BuildParams())
    assert model.groups == () and len(labels) == 0


def test_each_group_keeps_its_own_ladder_share_when_groups_alternate() -> None:
    # The share at the ladder is kept per group once computed: asked in turn, each group still gets its own.
    model = log_model((exp_group(0.9, -0.01, 0.1, -0.4), exp_group(0.98, -0.2, 0.02, -0.01)))
    flat = np.ones(5)  # a Sim table with no loss: the t table is the group's share itself
    for group in (0, 1, 0, 1, 7):
        assert_allclose(model.t_table(group, np.linspace(0, 1, 5), flat), model.loss_share(group, LADDER), atol=0)


def test_fitting_the_scale_model_reads_each_contour_once_besides_the_references() -> None:
    # A big build's contours wait in a scratch file and each read unpickles one: the size-and-shape features
    # are found once for the grouping and the choice of references, not once for each.
    from engine.ccsm.regression import REFERENCES_PER_GROUP

    class CountingContours(list):
        reads = 0

        def __getitem__(self, i):  # noqa: ANN001, ANN204 - list's
            CountingContours.reads += 1
            return super().__getitem__(i)

        def __iter__(self):  # noqa: ANN204 - list's
            return (self[i] for i in range(len(self)))

    contours = CountingContours(synthetic_contours(40))
    params = BuildParams()
    fit_scale_model(contours, params)
    assert 40 <= CountingContours.reads <= 40 + params.groups * REFERENCES_PER_GROUP
