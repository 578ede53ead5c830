"""Crossings between contours: detection, and the build's repair (docs/design.md section 5)."""

import numpy as np
import pytest
import shapely

from engine.ccsm.build import build_contour_set
from engine.ccsm.regression import t_for_scale
from engine.ccsm.topology import InputTouches, crossing_pairs, sweep_contacts
from engine.params import BuildParams
from engine.types import Contour, ContourSet


def test_crossing_pairs_finds_crossing_and_touching_lines_but_not_disjoint_ones() -> None:
    a = np.array([[0.0, 0.0], [10.0, 10.0]])
    b = np.array([[0.0, 10.0], [10.0, 0.0]])  # crosses a
    c = np.array([[20.0, 0.0], [30.0, 0.0]])  # far away
    d = np.array([[30.0, 0.0], [30.0, 5.0]])  # touches c at its end
    assert crossing_pairs([a, b, c, d]) == {(0, 1), (2, 3)}


def test_crossing_pairs_sees_a_crossing_deep_inside_long_lines() -> None:
    x = np.linspace(0.0, 10_000.0, 2001)
    a = np.column_stack([x, np.zeros_like(x)])
    b = np.column_stack([x, np.full_like(x, 1.0)])
    b[1000, 1] = -1.0  # one vertex dips below a, far from both ends
    assert crossing_pairs([a, b]) == {(0, 1)}
    assert crossing_pairs([a, b], only={1}) == {(0, 1)}


def nested_noisy_rings(n_rings: int = 6, gap_m: float = 20.0, seed: int = 3) -> ContourSet:
    """Concentric rings 20 m apart with 8 m noise: DP at 50 m cuts chords through the neighbours."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 2 * np.pi, 240, endpoint=False)
    contours = []
    for k in range(n_rings):
        r = 1_000.0 + k * gap_m + rng.uniform(-6.0, 6.0, len(s))
        xy = np.column_stack([r * np.cos(s), 0.6 * r * np.sin(s)]) + [500_000.0, 4_000_000.0]
        contours.append(Contour(k, 100.0 + 20 * k, xy, closed=True))
    return ContourSet(contours, "EPSG:32616", "EPSG:32616")


def crossings_over_scales(built) -> int:  # type: ignore[no-untyped-def]
    allowed = crossing_pairs([s.at(0.0) for s in built.surfaces])
    found = set()
    for scale in np.geomspace(built.model.source_scale, built.model.target_scale, 40):
        visible = [s for s in built.surfaces if s.vanish_scale > scale]
        lines = [s.at(t_for_scale(built.model.ladder, s.t_at_scale, float(scale))) for s in visible]
        found |= {(visible[a].contour_id, visible[b].contour_id) for a, b in crossing_pairs(lines)}
    return len(found - {(built.surfaces[a].contour_id, built.surfaces[b].contour_id) for a, b in allowed})


@pytest.fixture(scope="module")
def rings() -> ContourSet:
    rings = nested_noisy_rings()
    assert not crossing_pairs([np.vstack([c.coords, c.coords[:1]]) for c in rings.contours])
    return rings


def test_without_repair_the_dp_targets_of_close_contours_cross(rings: ContourSet) -> None:
    built = build_contour_set(rings, BuildParams(resolve_crossings=False), workers=1)
    assert crossings_over_scales(built) > 0


def test_repair_leaves_no_crossing_at_any_scale(rings: ContourSet) -> None:
    built = build_contour_set(rings, BuildParams(), workers=1)
    assert built.repaired > 0
    assert crossings_over_scales(built) == 0
    assert all(0.0 <= s.tolerance_factor <= 1.0 for s in built.surfaces)


def moving_zigzags(seed: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Eight zigzag lines 3 m apart whose vertices each move up to 4 m on a straight path."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 60.0, 13)
    start = [np.column_stack([x, 3.0 * k + rng.uniform(-0.8, 0.8, len(x))]) for k in range(8)]
    end = [line + rng.uniform(-2.0, 2.0, line.shape) for line in start]
    return start, end


@pytest.mark.parametrize("seed", range(6))
def test_sweep_contacts_agree_with_a_dense_sampling_of_the_motion(seed: int) -> None:
    start, end = moving_zigzags(seed)
    found = sweep_contacts(start, end)
    lams = np.linspace(0.0, 1.0, 4001)
    # Between two samples no point moves more than this: a contact lies that close to a sample's lines.
    step = max(float(np.hypot(*(b - a).T).max()) for a, b in zip(start, end, strict=True)) / 4000
    coords = np.array([[a + lam * (b - a) for a, b in zip(start, end, strict=True)] for lam in lams])
    lines = shapely.linestrings(coords.reshape(-1, 2), indices=np.repeat(np.arange(coords.shape[0] * 8), 13))
    lines = lines.reshape(len(lams), 8)
    i, j = np.triu_indices(8, 1)
    hit = shapely.intersects(lines[:, i], lines[:, j]).any(axis=0)
    close = (shapely.distance(lines[:, i], lines[:, j]) <= step).any(axis=0)
    met = {(int(a), int(b)) for a, b in zip(i[hit], j[hit], strict=True)}
    near = {(int(a), int(b)) for a, b in zip(i[close], j[close], strict=True)}
    assert met <= found  # every contact the sampling sees is found
    assert found <= near  # and every contact found is real
    assert met  # the motions do make lines meet


def test_sweep_contacts_find_touching_and_passing_through() -> None:
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    v_start = np.array([[5.0, 4.0], [6.0, 8.0], [7.0, 4.0]])
    still = v_start + [3.0, 0.0]  # slides sideways, never down
    assert sweep_contacts([line, v_start], [line, still]) == set()
    grazing = v_start + [0.0, -4.0]  # its lowest vertices come down exactly onto the line
    assert sweep_contacts([line, v_start], [line, grazing]) == {(0, 1)}
    through = v_start.copy()
    through[:, 1] -= 12.0  # the whole line moves down through `line`, apart at both ends
    assert sweep_contacts([line, v_start], [line, through]) == {(0, 1)}
    assert not crossing_pairs([line, v_start]) and not crossing_pairs([line, through])


def test_input_touches_knows_lines_that_meet_in_the_input_pair_by_pair() -> None:
    a = np.array([[0.0, 0.0], [10.0, 0.0]])
    saddle = np.array([[5.0, 1e-9], [5.0, 5.0]])  # a hair above a: touching, as lines of one level at a saddle
    apart = np.array([[5.0, 0.5], [5.0, 5.0]])
    touches = InputTouches([a, saddle, apart])
    assert (0, 1) in touches
    assert (0, 2) not in touches
    assert (1, 2) in touches  # they overlap along x = 5


class _CountingLines(list):
    """Lines that count how often each is read, one by one or together (as the spool's base rows are)."""

    def __init__(self, lines: list[np.ndarray]) -> None:
        super().__init__(lines)
        self.reads: list[int] = []

    def take(self, indices: list[int]) -> list[np.ndarray]:
        self.reads.extend(indices)
        return [self[i] for i in indices]


def test_input_touches_learned_together_answer_as_pair_by_pair() -> None:
    """Pairs asked together (``learn``) get the answers of pairs asked one by one, on lines that touch within
    INPUT_TOUCH_M, cross, overlap, share an end or stay apart by a little more, and each line is read once."""
    rng = np.random.default_rng(5)
    base = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    lines = [base]
    for _ in range(40):
        k = int(rng.integers(0, 5))
        offset = [0.0, 1e-7, 5e-7, 2e-6, 1e-3][k]  # touching up to 1e-6, apart beyond
        x = rng.uniform(1, 9)
        lines.append(np.array([[x, offset], [x + rng.uniform(-1, 1), 3.0]]))  # above the base's first segment
    lines.append(np.array([[5.0, -1.0], [5.0, 1.0]]))  # crossing
    lines.append(np.array([[10.0, 10.0], [12.0, 12.0]]))  # sharing an end
    counting = _CountingLines(lines)
    pairs = {(0, j) for j in range(1, len(lines))} | {(i, i + 1) for i in range(1, len(lines) - 1)}
    learned = InputTouches(counting)
    learned.learn(pairs)
    one_by_one = InputTouches(lines)
    answers = {pair: pair in one_by_one for pair in pairs}
    assert {pair: pair in learned for pair in pairs} == answers
    assert sorted(counting.reads) == list(range(len(lines)))  # each line read once, for every pair it is in
    with_base = [answers[(0, j)] for j in range(1, len(lines))]
    assert any(with_base) and not all(with_base)
