"""Synthetic contour shapes in metres of a projected (UTM-like) CRS, shared by the fixtures and the tests.

A plain module (not conftest.py) so test modules can import it by name: ``from synthetic_shapes import ...``.
"""

from __future__ import annotations

import numpy as np

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
