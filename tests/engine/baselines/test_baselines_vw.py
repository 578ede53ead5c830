"""Visvalingam–Whyatt (engine.baselines.vw) against a plain-Python reference of the same definition."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from engine.baselines import effective_areas, ladder
from engine.baselines.vw import vw_removal

HYPOTHESIS = settings(deadline=None, max_examples=80)


# --- plain-Python reference -------------------------------------------------------------------------------


def reference_vw(points: list[tuple[float, float]], closed: bool) -> tuple[list[float], list[int]]:
    """Textbook Visvalingam–Whyatt in O(n²): effective area and removal rank of each vertex.

    Repeatedly removes the vertex of smallest current area (ties: lowest index); the two neighbours get their
    triangle area again, raised to the area of the vertex just removed (Visvalingam and Whyatt's monotone
    rule). A line keeps both ends, a ring three vertices. Never-removed vertices get ``inf`` and the highest
    ranks in index order.
    """
    n = len(points)

    def tri(a: int, b: int, c: int) -> float:
        (ax, ay), (bx, by), (cx, cy) = points[a], points[b], points[c]
        return 0.5 * abs((bx - ax) * (cy - ay) - (cx - ax) * (by - ay))

    alive = list(range(n))
    area: dict[int, float] = {}

    def neighbours(i: int) -> tuple[int, int]:
        k = alive.index(i)
        return alive[(k - 1) % len(alive)], alive[(k + 1) % len(alive)]

    for i in alive:
        if closed or 0 < i < n - 1:
            p, q = neighbours(i)
            area[i] = tri(p, i, q)
    eff = [math.inf] * n
    rank = [-1] * n
    last = 0.0
    r = 0
    floor = 3 if closed else 2
    while area and len(alive) > floor:
        i = min(area, key=lambda j: (area[j], j))
        last = max(last, area.pop(i))
        eff[i], rank[i] = last, r
        r += 1
        p, q = neighbours(i)
        alive.remove(i)
        for j in (p, q):
            if j in area:
                jp, jq = neighbours(j)
                area[j] = max(tri(jp, j, jq), last)
    for i in range(n):
        if rank[i] < 0:
            rank[i] = r
            r += 1
    return eff, rank


integer_points = st.lists(
    st.tuples(st.integers(-50, 50), st.integers(-50, 50)), min_size=3, max_size=40
)


@given(points=integer_points, closed=st.booleans())
@HYPOTHESIS
def test_effective_areas_match_the_reference(points: list[tuple[int, int]], closed: bool) -> None:
    # Integer coordinates make every area exact, so ties (frequent here) must resolve identically.
    xy = np.array(points, dtype=np.float64)
    eff, rank = vw_removal(xy, closed)
    ref_eff, ref_rank = reference_vw([(float(x), float(y)) for x, y in points], closed)
    assert eff.tolist() == ref_eff
    assert rank.tolist() == ref_rank


@given(seed=st.integers(0, 10_000), n=st.integers(3, 200), closed=st.booleans())
@HYPOTHESIS
def test_areas_are_monotone_along_the_removal_order(seed: int, n: int, closed: bool) -> None:
    rng = np.random.default_rng(seed)
    xy = rng.normal(0.0, 100.0, (n, 2))
    eff, rank = vw_removal(xy, closed)
    removed = np.argsort(rank)[: n - (3 if closed else 2)]
    assert np.all(np.diff(eff[removed]) >= 0.0)
    kept = np.isinf(eff)
    assert kept.sum() == min(n, 3 if closed else 2)
    if not closed:
        assert kept[0] and kept[-1]


def test_hand_computed_example() -> None:
    # Vertex 2's triangle (0.5 m²) goes first; vertex 1's triangle is then (0,0)-(1,1)-(3,0): 1.5 m².
    xy = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 0.0]])
    assert effective_areas(xy, closed=False).tolist() == [math.inf, 1.5, 0.5, math.inf]


def test_monotone_rule_raises_a_smaller_recomputed_area() -> None:
    # Vertex 2 goes first (0.5 m², tied with vertex 3, lower index). Vertex 1 is then collinear with its new
    # neighbours 0 and 3 (area 0): the rule raises it to 0.5 instead of letting it go "before" vertex 2.
    xy = np.array([[2.0, 0.0], [4.0, 2.0], [4.0, 3.0], [3.0, 1.0], [3.0, 0.0]])
    eff, rank = vw_removal(xy, False)
    assert eff.tolist() == [math.inf, 0.5, 0.5, 0.5, math.inf]
    assert rank.tolist()[1:4] == [1, 0, 2]


def test_square_with_a_notch_loses_the_notch_first() -> None:
    ring = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [5.0, 9.0], [0.0, 10.0]])
    eff = effective_areas(ring, closed=True)
    assert int(np.argmin(eff)) == 3
    levels = ladder("vw", ring, closed=True, levels=3)
    assert [len(level) for level in levels] == [5, 4, 3]
    assert [5.0, 9.0] not in levels[1].tolist()


def test_large_input_runs_in_n_log_n() -> None:
    # 200,000 vertices would take minutes in O(n²); the heap does it in well under a second.
    rng = np.random.default_rng(3)
    xy = np.cumsum(rng.normal(0.0, 1.0, (200_000, 2)), axis=0)
    eff, rank = vw_removal(xy, False)
    assert np.isinf(eff).sum() == 2
    assert_array_equal(np.sort(rank), np.arange(200_000))
