"""Morph tiles: contours that would meet while a client morphs them are held still (engine.tiles.morph_untangle,
issue 13). The client's drawing is recomputed here at fine steps of the level and checked with
``engine.ccsm.topology.proper_crossing_pairs``."""

from __future__ import annotations

import numpy as np

from engine.ccsm.topology import proper_crossing_pairs
from engine.tiles.morph_untangle import MorphParts, morph_weights, untangle


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
