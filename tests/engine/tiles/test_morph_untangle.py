"""Morph tiles: contours that would cross while a client morphs them are held still (engine.tiles.morph_untangle,
issue 13), at any fraction of the level. The client's drawing is recomputed here at fine steps of the level and
at chosen moments, and checked with ``engine.ccsm.topology.proper_crossing_pairs``."""

from __future__ import annotations

import numpy as np

from engine.ccsm.topology import proper_crossing_pairs
from engine.tiles.morph_crossings import MorphParts, morph_crossing_pairs
from engine.tiles.morph_untangle import morph_weights, untangle

#: Frames per level the ccsm-morph plugin draws (web/plugin/src/index.js, stepsPerZoom).
PLUGIN_FRAMES = 32


def parts_of(starts: list[list[list[int]]], ends: list[list[list[int]]]) -> MorphParts:
    lens = np.array([len(s) for s in starts])
    return MorphParts(
        np.concatenate([np.array(s) for s in starts]),
        np.concatenate([np.array(e) for e in ends]),
        lens,
        np.arange(len(starts)),
    )


def drawn_at(parts: MorphParts, w: np.ndarray, f: float) -> list[np.ndarray]:
    """The client's drawing at fraction f: w piecewise linear between the nine steps (docs/morph-tiles.md)."""
    k = min(int(8 * f), 7)
    wf = w[k] + (8 * f - k) * (w[k + 1] - w[k])
    cut = np.cumsum(parts.part_len)[:-1]
    starts, ends = np.split(parts.start.astype(float), cut), np.split(parts.end.astype(float), cut)
    return [s + wf[o] * (e - s) for s, e, o in zip(starts, ends, parts.part_owner, strict=True)]


def crossings_through_the_level(parts: MorphParts, w: np.ndarray) -> int:
    return sum(len(proper_crossing_pairs(drawn_at(parts, w, f))) for f in np.linspace(0, 1, 161))


# A stays on y = 0; B, tilted, moves from above A to below it, its right end first: it crosses A on the way.
# Both ends are clean.
A = [[0, 0], [10, 0]]
B_START, B_END = [[2, 2], [8, 1]], [[2, -2], [8, -5]]
W = morph_weights(np.column_stack([np.full(9, 0.3), np.linspace(0.6, 0.2, 9), np.full(9, 0.5)]))


def held_shapes(shapes: dict[int, list[list[int]]]):  # type: ignore[no-untyped-def]
    """A ``snap`` callable giving these held shapes per contour (start equal to end); counts its calls."""
    calls = []

    def snap() -> MorphParts:
        calls.append(1)
        owners = sorted(shapes)
        pts = np.concatenate([np.array(shapes[o]) for o in owners])
        return MorphParts(pts, pts, np.array([len(shapes[o]) for o in owners]), np.array(owners))

    return snap, calls


def test_weights_are_the_clients() -> None:
    assert W[:, 0].tolist() == W[:, 2].tolist() == [0.0] * 9  # t does not change: w stays 0
    np.testing.assert_allclose(W[:, 1], np.linspace(0, 1, 9))


def test_lines_that_pass_through_each_other_are_held_still() -> None:
    parts = parts_of([A, B_START], [A, B_END])
    assert crossings_through_the_level(parts, W) > 0  # the case really happens
    snap, _ = held_shapes({0: A, 1: [[2, -2], [8, -5]]})
    out, held = untangle(parts, W, snap)
    assert held == 2
    assert crossings_through_the_level(out, W) == 0
    assert crossings_through_the_level(out, W) == 0
    np.testing.assert_array_equal(out.start, out.end)  # both drawn still


def test_a_moving_line_that_meets_a_held_one_is_held_in_turn() -> None:
    c = [[20, -3], [20, -1]]  # never meets A or B's motion, but crosses B's held shape
    parts = parts_of([A, B_START, c], [A, B_END, c])
    snap, _ = held_shapes({0: A, 1: [[2, -2], [25, -2]], 2: [[20, -3], [20, -2]]})
    out, held = untangle(parts, W, snap)
    assert held == 3
    assert crossings_through_the_level(out, W) == 0


def test_lines_apart_all_level_long_are_left_as_they_are() -> None:
    far = [[0, 9], [4, 9], [10, 9]]
    parts = parts_of([A, far, [[30, 0], [40, 0]]], [A, [[0, 5], [4, 5], [10, 5]], [[30, 0], [40, 0]]])
    snap, calls = held_shapes({})
    out, held = untangle(parts, W, snap)
    assert held == 0 and not calls
    np.testing.assert_array_equal(out.end, parts.end)


def test_lines_crossing_already_at_the_start_are_held() -> None:
    # No vertex ever meets the other line, so only the check at the start can see this crossing.
    x1, x2 = [[0, 0], [10, 10]], [[0, 10], [10, 0]]
    parts = parts_of([x1, x2], [[[0, 0], [10, 10]], [[0, 10], [10, 0]]])
    snap, _ = held_shapes({0: x1, 1: [[0, 10], [5, 5], [10, 0]]})
    out, held = untangle(parts, W, snap)
    assert held == 2
    assert crossings_through_the_level(out, W) == 0


# B, a short upright segment, sweeps 320 units to the right through the level (w = f: 10 units per plugin frame)
# and passes over A, one unit long, only while its x is in (0, 1): f in (165/320, 166/320), between the plugin's
# frames 16/32 and 17/32. At every frame the two are apart.
SPUR = [[0, 0], [1, 0]]
SWEEPER_START, SWEEPER_END = [[-165, -1], [-165, 1]], [[155, -1], [155, 1]]
BETWEEN_FRAMES = 165.5 / 320


def test_issue_13_a_crossing_between_the_plugins_frames_is_held() -> None:
    parts = parts_of([SPUR, SWEEPER_START], [SPUR, SWEEPER_END])
    frames = np.arange(PLUGIN_FRAMES + 1) / PLUGIN_FRAMES
    assert all(not proper_crossing_pairs(drawn_at(parts, W, f)) for f in frames)  # no frame shows it
    assert proper_crossing_pairs(drawn_at(parts, W, BETWEEN_FRAMES)) == {(0, 1)}  # a client at 0.517 does
    snap, calls = held_shapes({0: SPUR, 1: SWEEPER_END})
    out, held = untangle(parts, W, snap)
    assert held == 2 and calls  # both, each at its held shape
    assert not proper_crossing_pairs(drawn_at(out, W, BETWEEN_FRAMES))
    assert crossings_through_the_level(out, W) == 0


def test_a_line_grazing_another_at_one_moment_is_not_held() -> None:
    # B's lower end slides down onto A and stops there at the level's end: touching (a vertex on the other
    # line, which the grid may force on lines closer than a unit), never crossing.
    b_end = [[5, 0], [5, 4]]
    parts = parts_of([A, [[5, 2], [5, 4]]], [A, b_end])
    snap, calls = held_shapes({0: A, 1: b_end})
    out, held = untangle(parts, W, snap)
    assert held == 0 and not calls
    np.testing.assert_array_equal(out.end, parts.end)


def sides(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Sign of the turn a -> b -> c, broadcast over (..., 2) points."""
    turn = (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
    return np.sign(turn)


def brute_force_pairs(starts, ends, w, samples: int) -> set[tuple[int, int]]:  # type: ignore[no-untyped-def]
    """Pairs seen crossing properly at ``samples`` moments of every step (a lower bound of the exact answer)."""
    lam = np.linspace(0, 1, samples)
    wf = np.concatenate([w[k] + lam[:, None] * (w[k + 1] - w[k]) for k in range(w.shape[0] - 1)])  # (moments, n)
    lines = [s + wf[:, i, None, None] * (e - s) for i, (s, e) in enumerate(zip(starts, ends, strict=True))]
    found = set()
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            p1, p2 = lines[i][:, :-1, None], lines[i][:, 1:, None]
            q1, q2 = lines[j][:, None, :-1], lines[j][:, None, 1:]
            proper = (sides(p1, p2, q1) * sides(p1, p2, q2) < 0) & (sides(q1, q2, p1) * sides(q1, q2, p2) < 0)
            if proper.any():
                found.add((i, j))
    return found


def test_exact_pairs_agree_with_fine_sampling_on_random_motions() -> None:
    # Short random lines on a small grid, each moving with its own piecewise-linear weights: every pair that
    # sampling 41 moments per step sees crossing is found, and every pair found that those moments miss is seen
    # by 2,001 moments per step (a crossing found is real, not a rounding artefact).
    rng = np.random.default_rng(13)
    missed, between_samples, unconfirmed, found_total = 0, 0, 0, 0
    for _ in range(60):
        n = 5
        lens = rng.integers(2, 5, n)
        start = rng.integers(0, 24, (lens.sum(), 2))
        end = start + rng.integers(-8, 9, (lens.sum(), 2))
        w = np.sort(rng.random((9, n)), axis=0)
        w = (w - w[0]) / (w[-1] - w[0])
        exact = morph_crossing_pairs(MorphParts(start, end, lens, np.arange(n)), w)
        cut = np.cumsum(lens)[:-1]
        starts, ends = np.split(start.astype(float), cut), np.split(end.astype(float), cut)
        coarse = brute_force_pairs(starts, ends, w, 41)
        missed += len(coarse - exact)
        if exact - coarse:
            between_samples += len(exact - coarse)
            unconfirmed += len(exact - coarse - brute_force_pairs(starts, ends, w, 2001))
        found_total += len(exact)
    assert found_total > 100  # the motions really cross
    assert between_samples > 0  # and some only between the coarse moments
    assert missed == 0
    assert unconfirmed == 0
