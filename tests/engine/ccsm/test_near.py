"""The compiled near-piece kernels against the GEOS answers they replace (engine/ccsm/near.py)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.ccsm.near import box_pairs, boxes_meeting, lines_within, piece_gaps


def _strtree_pairs(a: np.ndarray, b: np.ndarray) -> set[tuple[int, int]]:
    tree = shapely.STRtree(shapely.box(b[:, 0], b[:, 1], b[:, 2], b[:, 3]))
    i, j = tree.query(shapely.box(a[:, 0], a[:, 1], a[:, 2], a[:, 3]))
    return set(zip(i.tolist(), j.tolist(), strict=True))


def _random_boxes(rng: np.random.Generator, n: int, grid: bool) -> np.ndarray:
    lo = rng.integers(0, 20, (n, 2)).astype(float) if grid else rng.uniform(0, 100, (n, 2))
    size = rng.integers(0, 4, (n, 2)).astype(float) if grid else rng.exponential(5, (n, 2))
    return np.hstack([lo, lo + size])


@pytest.mark.parametrize("grid", [False, True])
def test_box_pairs_are_the_strtree_pairs(grid: bool) -> None:
    """Random boxes, and boxes on an integer grid (many touch at an edge or a corner, many share a minx, some
    are points or segments): the same pairs as the STRtree query, each once, sorted."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = _random_boxes(rng, 150, grid), _random_boxes(rng, 200, grid)
        ia, ib = box_pairs(a, b)
        pairs = list(zip(ia.tolist(), ib.tolist(), strict=True))
        assert pairs == sorted(set(pairs))
        assert set(pairs) == _strtree_pairs(a, b)
    ia, ib = box_pairs(a, a)  # a set against itself, as the sweep index asks
    assert set(zip(ia.tolist(), ib.tolist(), strict=True)) == _strtree_pairs(a, a)


def test_box_pairs_touching_and_empty() -> None:
    unit = np.array([[0.0, 0.0, 1.0, 1.0]])
    touching = np.array([[1.0, 1.0, 2.0, 2.0], [1.0, -1.0, 1.0, 0.0], [1.0 + 1e-12, 0.0, 2.0, 1.0]])
    assert box_pairs(unit, touching)[1].tolist() == [0, 1]  # corner and edge touches meet; a gap does not
    assert box_pairs(unit, np.zeros((0, 4)))[0].tolist() == []


@pytest.mark.parametrize("grid", [False, True])
def test_boxes_meeting_are_the_strtree_boxes_met(grid: bool) -> None:
    """The mask of the boxes of b that meet some box of a is the set of b's boxes in the STRtree's pairs (edge
    and corner touches, shared minx, point and segment boxes on the grid), sparse and crowded."""
    rng = np.random.default_rng(4)
    for n in (5, 40, 150, 150):
        a, b = _random_boxes(rng, n, grid), _random_boxes(rng, 200, grid)
        met = boxes_meeting(a, b)
        assert set(np.flatnonzero(met).tolist()) == {j for _, j in _strtree_pairs(a, b)}
    assert met.any() and not met.all()
    unit = np.array([[0.0, 0.0, 1.0, 1.0]])
    touching = np.array([[1.0, 1.0, 2.0, 2.0], [1.0, -1.0, 1.0, 0.0], [1.0 + 1e-12, 0.0, 2.0, 1.0], [-1, -1, 2, 2]])
    assert boxes_meeting(unit, touching).tolist() == [True, True, False, True]
    assert boxes_meeting(np.zeros((0, 4)), touching).tolist() == [False] * 4


def _pieces(rng: np.random.Generator, kind: str) -> np.ndarray:
    """A few points of a piece: random, or adversarial for the distance (shared or repeated points, collinear
    and overlapping runs, crossings, lines meeting at a vertex)."""
    n = int(rng.integers(2, 8))
    if kind == "random":
        return np.cumsum(rng.normal(0, 1, (n, 2)), axis=0) + rng.uniform(-3, 3, 2)
    if kind == "grid":  # integer points: touching, collinear, overlapping and crossing segments, repeats
        return rng.integers(-2, 3, (n, 2)).astype(float)
    if kind == "collinear":  # all on one line, some backtracking
        return np.outer(rng.uniform(-2, 2, n), [0.6, 0.8]) + [0.1, 0.1]
    return np.repeat(rng.integers(-2, 3, (1, 2)).astype(float), n, axis=0)  # "degenerate": one point repeated


@pytest.mark.parametrize("kind", ["random", "grid", "collinear", "degenerate"])
def test_piece_gaps_are_geos_distances(kind: str) -> None:
    """The gap of every pair is shapely's distance of the two linestrings (the same number, bit for bit, as the
    crossing check's decisions are made on it), on random pieces and on pieces made to touch, cross, overlap
    collinearly and collapse to a point; pieces against pieces of every kind."""
    rng = np.random.default_rng(7)
    kinds = ["random", "grid", "collinear", "degenerate"]
    lines = [_pieces(rng, kind) for _ in range(60)] + [_pieces(rng, kinds[k % 4]) for k in range(60)]
    sizes = np.array([len(x) for x in lines])
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    last = first + sizes - 1
    p, q = np.meshgrid(np.arange(60), np.arange(len(lines)), indexing="ij")
    p, q = p.ravel(), q.ravel()
    gaps = piece_gaps(np.concatenate(lines), first, last, p, q)
    geoms = shapely.linestrings(np.concatenate(lines), indices=np.repeat(np.arange(len(lines)), sizes))
    expected = shapely.distance(geoms[p], geoms[q])
    assert np.array_equal(gaps, expected)
    if kind != "degenerate":
        assert (gaps == 0).any() and (gaps > 0).any()  # the cases are mixed: meeting and apart pairs


@pytest.mark.parametrize("far", [False, True])
def test_piece_gaps_up_to_a_limit_are_the_gaps(far: bool) -> None:
    """With a limit per pair, every gap up to its limit is the gap itself, bit for bit, and every other one is
    above its limit: so the pairs kept (gap <= limit) and their gaps are those of the full measure. Limits are
    set exactly at, a rounding step either side of, and well around the gaps, on pieces of every kind."""
    rng = np.random.default_rng(17)
    kinds = ["random", "grid", "collinear", "degenerate"]
    lines = [_pieces(rng, kinds[k % 4]) + (rng.normal(0, 4, 2) if k % 3 else 0) for k in range(120)]
    if far:
        lines = [line + [500_000.0, 4_000_000.0] for line in lines]
    sizes = np.array([len(x) for x in lines])
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    last = first + sizes - 1
    p, q = rng.integers(0, 120, 4000), rng.integers(0, 120, 4000)
    points = np.concatenate(lines)
    gaps = piece_gaps(points, first, last, p, q)
    step = rng.choice([0.0, 1.0, -1.0, 0.0], len(p))
    limit = np.where(rng.random(len(p)) < 0.6, np.nextafter(gaps, gaps + step), gaps * rng.uniform(0, 2, len(p)))
    limited = piece_gaps(points, first, last, p, q, limit)
    kept = gaps <= limit
    assert np.array_equal(limited <= limit, kept)
    assert np.array_equal(limited[kept], gaps[kept])
    assert kept.any() and (~kept).any() and (gaps[kept] > 0).any()


def test_piece_gaps_far_coordinates() -> None:
    """At UTM-sized coordinates (where rounding differs most from small ones) the gaps are still GEOS's."""
    rng = np.random.default_rng(11)
    pts = rng.normal(0, 30, (400, 2)).cumsum(axis=0) + [500_000.0, 4_000_000.0]
    first = np.arange(0, 400, 5)
    last = first + 4
    p, q = rng.integers(0, 80, 2000), rng.integers(0, 80, 2000)
    geoms = shapely.linestrings(pts, indices=np.repeat(np.arange(80), 5))
    assert np.array_equal(piece_gaps(pts, first, last, p, q), shapely.distance(geoms[p], geoms[q]))


def _without_repeats(line: np.ndarray) -> np.ndarray:
    """The line without consecutive repeated points (as every contour: ``ccs.check_contour`` refuses them)."""
    return line[np.concatenate([[True], (np.diff(line, axis=0) != 0).any(axis=1)])]


def _geos_within(lines: list[np.ndarray], p: np.ndarray, q: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray]:
    """shapely.dwithin of the pairs, plain and with the first line prepared (as InputTouches asked it)."""
    geoms = [shapely.linestrings(line) for line in lines]
    plain = shapely.dwithin(np.array(geoms)[p], np.array(geoms)[q], d)
    prepared = np.array([shapely.linestrings(line) for line in lines])
    shapely.prepare(prepared)
    return plain, shapely.dwithin(prepared[p], np.array(geoms)[q], d)


def _check_within(lines: list[np.ndarray], p: np.ndarray, q: np.ndarray, d: float) -> np.ndarray:
    """lines_within of the pairs: exactly shapely.distance <= d, and shapely.dwithin's decision (plain and
    prepared) wherever the distance is not d itself up to rounding. At such a tie GEOS's dwithin rounds its own
    distance otherwise than its distance does (a pair 9.9999999992e-7 apart by shapely.distance is not within
    1e-6 by shapely.dwithin), so no test can agree with both there."""
    sizes = np.array([len(x) for x in lines])
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    got = lines_within(np.concatenate(lines), first, first + sizes - 1, p, q, d)
    geoms = np.array([shapely.linestrings(line) for line in lines])
    distance = shapely.distance(geoms[p], geoms[q])
    assert np.array_equal(got, distance <= d)
    magnitude = max(np.abs(np.concatenate(lines)).max(), d)
    clear = np.abs(distance - d) > 64 * np.finfo(float).eps * magnitude
    plain, prepared = _geos_within(lines, p, q, d)
    assert np.array_equal(got[clear], plain[clear])
    assert np.array_equal(got[clear], prepared[clear])
    return got


@pytest.mark.parametrize("kind", ["random", "grid", "collinear", "tiny"])
@pytest.mark.parametrize("far", [False, True])
def test_lines_within_is_geos_dwithin(kind: str, far: bool) -> None:
    """Every pair of lines gets shapely.dwithin's decision, at INPUT_TOUCH_M and at distances of the lines' own
    size, on lines shifted by a hair less or more than the distance (touching, crossing, overlapping
    collinearly, meeting at a vertex, exactly ``d`` apart on the grid, segments of 1e-9 m), at small and at
    UTM-sized coordinates, and on lines long enough to be cut into several chunks."""
    rng = np.random.default_rng(13)
    kinds = ["random", "grid", "collinear", "tiny"]
    origin = np.array([500_000.0, 4_000_000.0]) if far else np.zeros(2)
    lines = []
    for k in range(48):
        line = _pieces(rng, kind if k < 24 else kinds[k % 4]) if kind != "tiny" or k >= 24 else None
        if line is None:  # segments of a nanometre, around a point of the grid
            line = rng.integers(-2, 3, (1, 2)) + np.cumsum(rng.normal(0, 1e-9, (int(rng.integers(2, 6)), 2)), axis=0)
        if k % 6 == 0:  # long: several chunks of segments
            line = np.concatenate([line, line[-1] + np.cumsum(rng.normal(0, 0.3, (60, 2)), axis=0)])
        shift = rng.choice([0.0, 5e-7, 1e-6, 1.5e-6, 0.5, 1.0]) * rng.choice([-1.0, 1.0], 2)
        line = _without_repeats(line + shift + origin)
        if len(line) < 2:
            line = np.array([origin, origin + 1.0])
        lines.append(line)
    p, q = np.meshgrid(np.arange(len(lines)), np.arange(len(lines)), indexing="ij")
    p, q = p.ravel(), q.ravel()
    for d in (1e-6, 0.5, 1.0):
        got = _check_within(lines, p, q, d)
        assert got.any() and not got.all()  # the cases are mixed: pairs within and beyond d


_grid_lines = st.lists(st.tuples(st.integers(-4, 4), st.integers(-4, 4)), min_size=2, max_size=9).map(
    lambda pts: _without_repeats(np.array(pts, dtype=float))
).filter(lambda line: len(line) >= 2)


@settings(max_examples=300, deadline=None)
@given(
    a=_grid_lines,
    b=_grid_lines,
    scale=st.sampled_from([1e-6, 1e-3, 1.0, 7.3]),
    shift=st.tuples(st.sampled_from([0.0, 0.5, 1.0, 1e-7]), st.sampled_from([0.0, 0.5, -1.0, 1e-7])),
    d=st.sampled_from([0.0, 1e-6, 0.5, 1.0, 2.0**0.5]),
    far=st.booleans(),
)
def test_lines_within_agrees_with_dwithin_on_grid_lines(a, b, scale, shift, d, far) -> None:  # noqa: ANN001
    """Lines of grid points (crossing, touching at vertices and along segments, collinear, exactly d apart),
    scaled and shifted: the decision of shapely.dwithin, both ways round."""
    origin = np.array([500_000.0, 4_000_000.0]) if far else np.zeros(2)
    lines = [a * scale + origin, (b + shift) * scale + origin]
    _check_within(lines, np.array([0, 1]), np.array([1, 0]), d * scale)
