"""The four methods' ladders in one form, and the evaluation pipeline on a few synthetic contours."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from engine.baselines import ladder
from engine.errors import InvalidParameter
from engine.evaluation.levels import (
    EVAL_METHODS,
    SurfaceLadder,
    VertexLadder,
    contour_ladders,
    eval_params,
    ranks_from_levels,
)
from engine.evaluation.pipeline import evaluate_contour, evaluate_set
from engine.types import Contour, ContourSet


def noisy_ellipse(seed: int, n: int = 120, cx: float = 0.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1.0 + 0.08 * rng.standard_normal(n)
    return np.column_stack([cx + 800 * r * np.cos(a), 500 * r * np.sin(a)])


def wavy_line(seed: int, n: int = 80) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.linspace(0, 3000, n)
    return np.column_stack([x, 2000 + 200 * np.sin(x / 300) + 20 * rng.standard_normal(n)])


@pytest.fixture(scope="module")
def contours() -> list[Contour]:
    return [
        Contour(id="ring", elevation=100.0, coords=noisy_ellipse(1), closed=True),
        Contour(id="line", elevation=120.0, coords=wavy_line(2), closed=False),
    ]


def test_ranks_rebuild_every_level_of_every_baseline(contours: list[Contour]) -> None:
    for c in contours:
        for method in ("dp", "wm", "vw"):
            levels = ladder(method, c.coords, c.closed, 20)
            rank = ranks_from_levels(c.coords, levels)
            for i, level in enumerate(levels):
                assert_allclose(c.coords[rank >= i], level)


def test_ranks_handle_a_point_visited_twice() -> None:
    xy = np.array([[0, 0], [1, 1], [2, 0], [1, 1], [0, 2.0]])
    rank = ranks_from_levels(xy, [xy, xy[[0, 1, 2, 4]], xy[[0, 4]]])
    assert rank.tolist() == [2, 1, 1, 0, 2]
    with pytest.raises(InvalidParameter):
        ranks_from_levels(xy, [xy, xy[[4, 0]]])


def test_ladders_share_one_form(contours: list[Contour]) -> None:
    params = eval_params("extreme", 50_000, 500_000)
    for c in contours:
        ladders = contour_ladders(c, 30, params)
        assert set(ladders) == set(EVAL_METHODS)
        assert isinstance(ladders["ccsm"], SurfaceLadder)
        for method, lad in ladders.items():
            assert lad.levels == 30
            first, last = lad.at(0), lad.at(29)
            assert first.shape[1] == 2
            if method != "ccsm":
                assert isinstance(lad, VertexLadder)
                assert len(first) == c.n_vertices
                assert len(last) == (3 if c.closed else 2)
            if not c.closed:
                assert_allclose(first[0], c.coords[0])
                assert_allclose(last[-1], c.coords[-1])


def test_similarity_curves_start_at_one_and_ccsm_is_smooth(contours: list[Contour]) -> None:
    params = eval_params("extreme", 50_000, 500_000)
    for c in contours:
        r = evaluate_contour(0, c, 50, params)
        assert r.sims.shape == (4, 50)
        assert_allclose(r.sims[:, 0], 1.0, atol=2e-3)
        jumps = np.max(np.abs(np.diff(r.sims, axis=1)), axis=1)
        assert jumps[0] < jumps[1]  # CCSM's largest step is smaller than DP's


def test_scale_target_stops_at_each_methods_own_result(contours: list[Contour]) -> None:
    params = eval_params("scale", 50_000, 500_000)
    ladders = contour_ladders(contours[0], 20, params)
    assert len(ladders["dp"].at(19)) > 3  # DP at 1:500,000 (50 m) keeps more than the minimal triangle


def test_evaluate_set_in_process(contours: list[Contour]) -> None:
    far = Contour(id="ring2", elevation=140.0, coords=noisy_ellipse(3, cx=5000.0), closed=True)
    cs = ContourSet(contours=[*contours, far], working_crs="EPSG:32616", source_crs="EPSG:32616")
    ev = evaluate_set(cs, levels=20, workers=1, table_contours=2)
    assert ev.sims.shape == (3, 4, 20)
    assert {r[0] for r in ev.crossings} == set(EVAL_METHODS)
    assert all(r[2] == 0 for r in ev.crossings if r[1] == 0)  # the input contours do not meet
    assert 1 <= len(ev.table_contours) <= 2
    with pytest.raises(InvalidParameter):
        evaluate_set(cs, levels=1)
