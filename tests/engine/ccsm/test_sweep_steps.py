"""The crossing checks of all ladder steps in one compiled pass (issue 12 item 6): the same pairs of lines as
checking step by step, on real contours."""

from __future__ import annotations

import numpy as np
import pytest

from engine.ccsm.build import BuiltSet, build_contour_set, checked_ladder_steps
from engine.ccsm.topology import SweepIndex, new_contact_pairs
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.params import BuildParams


@pytest.fixture(scope="module")
def sample_unrepaired() -> BuiltSet:
    """The bundled sample built without the repair: its slices meet in many pairs, at many steps."""
    return build_contour_set(read_source(sample_contours_path()), BuildParams(resolve_crossings=False), workers=1)


def step_by_step(built: BuiltSet, only: set[int] | None) -> set[tuple[int, int]]:
    """The union over the ladder's steps of :meth:`SweepIndex.contacts`, one step at a time."""
    surfaces, ladder = built.surfaces, built.model.ladder
    index = SweepIndex.of([s.base for s in surfaces], [s.top for s in surfaces], only)
    tables = np.array([s.t_at_scale for s in surfaces])
    vanish = np.array([s.vanish_scale for s in surfaces])
    found: set[tuple[int, int]] = set()
    for k in checked_ladder_steps(built.model):
        found |= index.contacts(tables[:, k], tables[:, k + 1], vanish > ladder[k])
    return found


@pytest.mark.parametrize("only_every", [None, 7])
def test_one_pass_over_the_steps_finds_the_pairs_of_the_step_by_step_check(
    sample_unrepaired: BuiltSet, only_every: int | None
) -> None:
    built = sample_unrepaired
    only = None if only_every is None else set(range(0, len(built.surfaces), only_every))
    expected = step_by_step(built, only)
    assert len(expected) > 20  # the unrepaired sample's slices do meet
    found = new_contact_pairs(built.surfaces, built.model.ladder, checked_ladder_steps(built.model), only)
    assert found == expected


def test_a_pair_meets_only_in_a_step_where_both_lines_are_shown() -> None:
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    up, down = np.array([[5.0, 5.0], [5.0, 9.0]]), np.array([[5.0, -5.0], [5.0, -1.0]])
    index = SweepIndex.of([line, up], [line, down])
    # Step 0 moves the second line a quarter of the way (still above), step 1 the rest (through the first).
    t0 = np.array([[0.0, 0.25], [0.0, 0.25]])
    t1 = np.array([[0.25, 1.0], [0.25, 1.0]])
    assert index.contacts_in_steps(t0, t1, np.ones((2, 2), dtype=bool)) == {(0, 1)}
    hidden_in_step_1 = np.array([[True, True], [True, False]])
    assert index.contacts_in_steps(t0, t1, hidden_in_step_1) == set()
    assert index.contacts_in_steps(t0[:, :1], t1[:, :1], np.ones((2, 1), dtype=bool)) == set()
