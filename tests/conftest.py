"""Shared fixtures: small synthetic contours in metres of a projected (UTM-like) CRS.

Every random fixture is seeded, so a failing test always sees the same input. Rings are stored without their
repeated first vertex (the :class:`engine.types.Contour` convention) and run counter-clockwise unless a
fixture says otherwise.
"""

from __future__ import annotations

import numpy as np
import pytest

from engine.types import Contour

#: A plausible UTM position (zone 16N near Jacksboro): far from the origin, as real working coordinates are.
ORIGIN_M = np.array([750_000.0, 4_060_000.0])


def circle_coords(radius_m: float, n: int, centre: np.ndarray = ORIGIN_M) -> np.ndarray:
    """``n`` vertices of a counter-clockwise circle, first vertex on the +x axis, (n, 2) metres."""
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return centre + radius_m * np.column_stack([np.cos(angle), np.sin(angle)])


def noisy_ellipse_coords(seed: int, a_m: float = 1500.0, b_m: float = 800.0, n: int = 240) -> np.ndarray:
    """A counter-clockwise ellipse with seeded radial noise (a few per cent of the radius), (n, 2) metres."""
    rng = np.random.default_rng(seed)
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    radial = 1.0 + 0.03 * rng.standard_normal(n)
    xy = np.column_stack([a_m * np.cos(angle), b_m * np.sin(angle)]) * radial[:, None]
    return ORIGIN_M + xy


def noisy_line_coords(seed: int, n: int = 150, step_m: float = 20.0) -> np.ndarray:
    """An open line heading east with a seeded random walk across it, (n, 2) metres."""
    rng = np.random.default_rng(seed)
    x = np.arange(n) * step_m
    y = np.cumsum(rng.normal(0.0, 0.4 * step_m, n))
    return ORIGIN_M + np.column_stack([x, y])


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
