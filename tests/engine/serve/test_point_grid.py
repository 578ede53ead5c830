"""The grid a tile's label layer finds its anchors with: it may return points around a rectangle, never miss
one inside it."""

from __future__ import annotations

import numpy as np
import pytest

from engine.serve.point_grid import PointGrid


def inside(xy: np.ndarray, minx: float, miny: float, maxx: float, maxy: float) -> np.ndarray:
    return np.flatnonzero((xy[:, 0] >= minx) & (xy[:, 0] <= maxx) & (xy[:, 1] >= miny) & (xy[:, 1] <= maxy))


@pytest.mark.parametrize("n", [1, 7, 5000])
def test_every_point_inside_a_rectangle_is_found_and_few_beyond_it(n: int) -> None:
    rng = np.random.default_rng(n)
    xy = rng.uniform([1e6, 4e6], [1.1e6, 4.05e6], size=(n, 2))
    xy[: n // 10] = np.round(xy[: n // 10], -3)  # points on cell-like round coordinates, and repeated ones
    grid = PointGrid.of(xy)
    found_beyond = 0
    for _ in range(300):
        x0, x1 = np.sort(rng.uniform(0.98e6, 1.12e6, 2))
        y0, y1 = np.sort(rng.uniform(3.98e6, 4.07e6, 2))
        near = grid.near(x0, y0, x1, y1)
        assert np.all(np.diff(near) > 0)  # ascending, no point twice
        exact = inside(xy, x0, y0, x1, y1)
        assert np.isin(exact, near).all()
        found_beyond += len(near) - len(exact)
    if n == 5000:  # the grid looks near the rectangle, not at everything
        assert found_beyond < 0.2 * 300 * n


def test_points_on_a_rectangle_edge_are_found() -> None:
    corners = [[0.0, 0.0], [10.0, 10.0], [5.0, 5.0], [10.0, 0.0]]
    xy = np.array([*corners, *np.random.default_rng(1).uniform(0, 10, (60, 2))])
    grid = PointGrid.of(xy)
    for box in [(10.0, 0.0, 10.0, 0.0), (5.0, 5.0, 10.0, 10.0), (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 5.0, 5.0)]:
        assert set(inside(xy, *box).tolist()) <= set(grid.near(*box).tolist()), box


def test_points_on_one_line_and_no_points() -> None:
    xy = np.column_stack([np.linspace(0, 100, 50), np.full(50, 7.0)])
    near = PointGrid.of(xy).near(20.0, 7.0, 40.0, 7.0)
    assert set(inside(xy, 20.0, 7.0, 40.0, 7.0).tolist()) <= set(near.tolist())
    assert len(near) < len(xy)
    assert len(PointGrid.of(np.zeros((0, 2))).near(0.0, 0.0, 1.0, 1.0)) == 0
