"""Compiled WM helpers (engine.baselines._wm_kernels) against plain references: shapely for segment contact,
the O(m) scan for the segment grid."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from engine.baselines._wm_kernels import (
    build_index,
    index_path_is_clear,
    init_links,
    mark_changed,
    path_is_clear,
    segments_meet,
)

HYPOTHESIS = settings(deadline=None, max_examples=150)

coordinate = st.integers(-6, 6)


@given(st.lists(coordinate, min_size=8, max_size=8))
@HYPOTHESIS
def test_segments_meet_agrees_with_shapely(c: list[int]) -> None:
    # Small integer coordinates: exact arithmetic and many touching, collinear and overlapping cases.
    # (A zero-length segment is a point to us but an invalid line to shapely: left out.)
    assume((c[0], c[1]) != (c[2], c[3]) and (c[4], c[5]) != (c[6], c[7]))
    a = shapely.LineString([(c[0], c[1]), (c[2], c[3])])
    b = shapely.LineString([(c[4], c[5]), (c[6], c[7])])
    assert segments_meet(*map(float, c)) == a.intersects(b)


def curly_line(seed: int, n: int) -> np.ndarray:
    """A seeded line of random steps and sharp random turns: it comes close to itself often."""
    rng = np.random.default_rng(seed)
    heading = np.radians(np.concatenate([[0.0], np.cumsum(rng.uniform(-100.0, 100.0, n - 2))]))
    steps = rng.uniform(5.0, 30.0, n - 1)[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


@given(seed=st.integers(0, 100_000), closed=st.booleans())
@settings(deadline=None, max_examples=60)
def test_grid_query_matches_the_full_scan(seed: int, closed: bool) -> None:
    # Random edits (shortcuts and displaced runs), applied one after another as the WM operators do: the grid,
    # kept up to date with mark_changed, must answer every query exactly as the O(m) scan over the links.
    rng = np.random.default_rng(seed)
    xy = curly_line(seed, 80)
    m = len(xy)
    prv, nxt = init_links(m, closed)
    dead = np.zeros(m, np.bool_)
    index = build_index(xy, nxt)
    agree = 0
    for _ in range(60):
        alive = np.flatnonzero(~dead)
        if len(alive) < 6:
            break
        pos = int(rng.integers(0, len(alive) - (0 if closed else 2)))
        a = int(alive[pos])
        run_len = int(rng.integers(1, 4))
        run = []
        v = a
        for _ in range(run_len):
            v = int(nxt[v])
            if v < 0:
                break
            run.append(v)
        b = int(nxt[run[-1]]) if run and run[-1] >= 0 else -1
        if not run or b < 0 or b == a or a in run or b in run:
            continue
        if rng.random() < 0.5:
            path = np.array([xy[a], xy[b]])
        else:
            # Displace the run perpendicular to its baseline, as exaggeration does.
            shift = rng.normal(0.0, 15.0, 2)
            path = np.vstack([xy[a], xy[run] + shift, xy[b]])
        start = run[0]
        # The run is contiguous in the compacted sense only through links: express it as (start, length) on
        # the original indices when it is, else skip (the kernels assume a contiguous run).
        if any(((run[0] + j) % m) != run[j] for j in range(len(run))):
            continue
        expected = path_is_clear(xy, prv, nxt, closed, a, b, path)
        got = index_path_is_clear(xy, nxt, dead, index, a, b, start, len(run), path)
        assert got == expected
        agree += 1
        if expected:  # apply the edit, as an operator would
            if len(path) == 2:
                dead[run] = True
                nxt[a] = b
                prv[b] = a
                mark_changed(index, a)
            else:
                xy[run] = path[1:-1]
                mark_changed(index, a)
                for v in run:
                    mark_changed(index, v)
    assert agree > 0
