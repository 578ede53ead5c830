"""Shared fixtures: small synthetic contours in metres of a projected (UTM-like) CRS.

Every random fixture is seeded, so a failing test always sees the same input. Rings are stored without their
repeated first vertex (the :class:`engine.types.Contour` convention) and run counter-clockwise unless a
fixture says otherwise.
"""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_shapes import ORIGIN_M, circle_coords, noisy_ellipse_coords, noisy_line_coords  # noqa: F401

from engine.types import Contour


@pytest.fixture(scope="session", autouse=True)
def own_cache_home(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A cache folder of the test run's own ($XDG_CACHE_HOME, where ``ccsm simplify`` keeps built sources): the
    tests neither read nor fill the user's cache."""
    import os

    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("xdg-cache"))


@pytest.fixture
def circle_ring() -> Contour:
    """A 72-vertex circle of radius 400 m."""
    return Contour(id="circle", elevation=100.0, coords=circle_coords(400.0, 72), closed=True)


@pytest.fixture
def noisy_ellipse_ring() -> Contour:
    """A 1500 m x 800 m ellipse, 240 vertices, seeded radial noise."""
    return Contour(id="ellipse", elevation=120.0, coords=noisy_ellipse_coords(seed=7), closed=True)


@pytest.fixture
def noisy_open_line() -> Contour:
    """An open line about 3 km long, 150 vertices, seeded random walk."""
    return Contour(id="line", elevation=140.0, coords=noisy_line_coords(seed=11), closed=False)


@pytest.fixture
def self_touching_loop() -> Contour:
    """A ring of two lobes that touch at one vertex (it visits (50, 0) twice), 100 m across."""
    local = np.array(
        [
            [0.0, 0.0],
            [50.0, 0.0],
            [100.0, 0.0],
            [100.0, 100.0],
            [55.0, 100.0],
            [50.0, 0.0],
            [45.0, 100.0],
            [0.0, 100.0],
        ]
    )
    return Contour(id="touching", elevation=160.0, coords=ORIGIN_M + local, closed=True)


@pytest.fixture
def tiny_ring() -> Contour:
    """An 8-vertex ring of radius 5 m: too small to show at 1:50,000 (0.5 mm there is 25 m)."""
    return Contour(id="tiny", elevation=180.0, coords=circle_coords(5.0, 8), closed=True)
