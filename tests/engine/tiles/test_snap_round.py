"""Snap rounding (engine.tiles.snap_round) and the crossing test on the grid (engine.tiles.crossings), issue 13.

The data are lines a third of a grid unit apart that never meet, turned by a random angle: plain rounding makes
them cross; snap rounding must not. The oracles are independent of the code under test: shapely for which pixels
a segment passes through, ``engine.ccsm.topology.proper_crossing_pairs`` for crossings.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from engine.ccsm.topology import proper_crossing_pairs
from engine.tiles.crossings import crossing_owner_pairs, lines_cross_in_grid
from engine.tiles.grid import drop_repeats
from engine.tiles.snap_round import snap_round

SEEDS = range(12)


def close_lines(seed: int, n_lines: int = 12, gap: float = 0.33) -> list[np.ndarray]:
    """Wavy lines ``gap`` units apart that never meet (each keeps its side of its neighbours at every shared
    x, and so in between), with extra vertices on their segments, turned and shifted at random."""
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, 40.0, 1.7)
    wave = 2.0 * np.sin(x / 3.0 + rng.uniform(0, 6))
    angle = rng.uniform(0, math.pi)
    turn = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    shift = rng.uniform(0, 1, 2) + 50.0
    lines = []
    for i in range(n_lines):
        y = wave + i * gap + rng.uniform(-0.4, 0.4, len(x)) * gap
        pts = np.column_stack([x, y])
        # Extra vertices on the segments move nothing but put vertices where the other lines have none.
        u = np.sort(rng.uniform(0, len(x) - 1, 3 * len(x)))
        k = np.minimum(u.astype(int), len(x) - 2)
        extra = pts[k] + (u - k)[:, None] * (pts[k + 1] - pts[k])
        order = np.argsort(np.concatenate([np.arange(len(x)), u]), kind="stable")
        lines.append(np.concatenate([pts, extra])[order] @ turn.T + shift)
    return lines


def snapped_lines(lines: list[np.ndarray]) -> tuple[list[np.ndarray], list[int]]:
    q, lens, src = snap_round(np.concatenate(lines), np.array([len(line) for line in lines]))
    return np.split(q, np.cumsum(lens)[:-1]), src.tolist()


def reference_snap(lines: list[np.ndarray]) -> list[np.ndarray]:
    """Snap rounding spelled out with shapely: the hot pixels a segment meets, in the order it enters them."""
    hot = {tuple(p) for p in np.floor(np.concatenate(lines) + 0.5).astype(int).tolist()}
    boxes = {h: shapely.box(h[0] - 0.5, h[1] - 0.5, h[0] + 0.5, h[1] + 0.5) for h in hot}
    out = []
    for line in lines:
        path = [tuple(np.floor(line[0] + 0.5).astype(int).tolist())]
        for p, q in zip(line[:-1], line[1:], strict=True):
            segment = shapely.LineString([p, q])
            met = []
            for h, box in boxes.items():
                if segment.intersects(box):
                    entry = min(segment.project(shapely.Point(c)) for c in shapely.get_coordinates(segment & box))
                    met.append((entry, h))
            for _, h in sorted(met):
                if h != path[-1]:
                    path.append(h)
        out.append(np.array(path))
    return [p for p in out if len(p) >= 2]


def test_the_lines_never_meet_and_plain_rounding_makes_them_cross() -> None:
    crossed = 0
    for seed in SEEDS:
        lines = close_lines(seed)
        geoms = shapely.linestrings(lines)
        assert not any(shapely.intersects(geoms[i], geoms[j]) for i in range(12) for j in range(i + 1, 12))
        rounded = [drop_repeats(np.rint(line).astype(np.int64)) for line in lines]
        crossed += len(proper_crossing_pairs([r for r in rounded if len(r) >= 2]))
    assert crossed > 10  # the data really are the hard case


@pytest.mark.parametrize("seed", SEEDS)
def test_snap_rounded_lines_never_cross(seed: int) -> None:
    snapped, _ = snapped_lines(close_lines(seed))
    assert proper_crossing_pairs(snapped) == set()


@pytest.mark.parametrize("seed", SEEDS[:4])
def test_snap_rounding_equals_the_reference(seed: int) -> None:
    lines = close_lines(seed, n_lines=6, gap=0.45)
    snapped, _ = snapped_lines(lines)
    want = reference_snap(lines)
    assert len(snapped) == len(want)
    for got, ref in zip(snapped, want, strict=True):
        np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("seed", SEEDS[:4])
def test_every_snapped_vertex_is_a_hot_pixel_the_line_passes_through(seed: int) -> None:
    lines = close_lines(seed)
    snapped, src = snapped_lines(lines)
    hot = {tuple(p) for p in np.floor(np.concatenate(lines) + 0.5).astype(int).tolist()}
    for line, k in zip(snapped, src, strict=True):
        assert {tuple(p) for p in line.tolist()} <= hot
        # A pixel's centre is within half its diagonal of any point of the pixel, so of the line.
        far = shapely.distance(shapely.linestrings(lines[k]), shapely.points(line.astype(float)))
        assert far.max() <= math.sqrt(2) / 2 + 1e-9


def test_a_line_inside_one_pixel_is_left_out() -> None:
    pts = np.array([[0.1, 0.1], [0.3, 0.2], [5.0, 5.0], [7.0, 5.0]])
    q, lens, src = snap_round(pts, np.array([2, 2]))
    assert lens.tolist() == [2] and src.tolist() == [1]
    assert q.tolist() == [[5, 5], [7, 5]]


def random_walks(seed: int, n: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lens = rng.integers(2, 8, n)
    pts = rng.integers(0, 25, (int(lens.sum()), 2))
    owner = rng.integers(0, n // 2, n)
    return pts, lens, owner


def owner_pairs_crossing_as_floats(pts: np.ndarray, lens: np.ndarray, owner: np.ndarray) -> set[tuple[int, int]]:
    """The pairs of owners whose parts cross properly by the float predicate: what the grid check must find."""
    parts = np.split(pts, np.cumsum(lens)[:-1])
    return {
        (min(owner[a], owner[b]), max(owner[a], owner[b]))
        for a, b in proper_crossing_pairs(parts)
        if owner[a] != owner[b]
    }


@pytest.mark.parametrize("seed", range(30))
def test_crossings_on_the_grid_agree_with_the_float_predicate(seed: int) -> None:
    pts, lens, owner = random_walks(seed)
    want = owner_pairs_crossing_as_floats(pts, lens, owner)
    assert crossing_owner_pairs(pts, lens, owner) == want
    assert lines_cross_in_grid(pts, lens, owner) == bool(want)


def wide_walks(seed: int, n: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Few lines of short and long steps over a whole buffered tile: the crossing check's grid then has cells
    many units wide, which long segments pass through by the dozen."""
    rng = np.random.default_rng(seed)
    lens = rng.integers(2, 12, n)
    steps = rng.integers(-40, 41, (int(lens.sum()), 2)) * rng.choice([1, 30], (int(lens.sum()), 1))
    starts = np.repeat(rng.integers(-64, 4160, (n, 2)), lens, axis=0)
    first = np.repeat(np.cumsum(lens) - lens, lens)
    pts = starts + np.cumsum(steps, axis=0) - np.cumsum(steps, axis=0)[first] + steps[first]
    owner = rng.integers(0, n // 2, n)
    return pts, lens, owner


@pytest.mark.parametrize("seed", range(20))
def test_crossings_over_a_whole_tile_agree_with_the_float_predicate(seed: int) -> None:
    pts, lens, owner = wide_walks(seed)
    want = owner_pairs_crossing_as_floats(pts, lens, owner)
    assert want  # the walks cross: the check has something to find
    assert crossing_owner_pairs(pts, lens, owner) == want
    assert lines_cross_in_grid(pts, lens, owner)


def test_a_crossing_far_from_the_grid_origin_between_long_segments_is_found() -> None:
    pts = np.array([[-64, -64], [4160, 4100], [-64, 4100], [4160, -60]])
    assert lines_cross_in_grid(pts, np.array([2, 2]), np.array([0, 1]))
    assert not lines_cross_in_grid(pts[[0, 1, 2, 0]], np.array([2, 2]), np.array([0, 1]))
