"""The interval-by-scale rule (issue 11, docs/design.md section 9): ranks, fade ranges, overrides."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from engine.cartography.options import CartographyOptions, check_schedule_fits
from engine.cartography.schedule import NEVER, make_schedule, parse_schedule
from engine.errors import InvalidParameter
from engine.tiles.scale import scale_for_zoom

#: Base intervals people use, in metres and feet.
BASES = [0.5, 1.0, 2.0, 2.5, 5.0, 10.0, 20.0, 25.0, 30.0, 40.0, 50.0, 100.0, 200.0, 250.0]
#: The usual series (1, 2, 2.5, 5 x 10^k).
SERIES = {round(m * 10.0**k, 9) for m in (1, 2, 2.5, 5) for k in range(-1, 6)}


def levels_of(base: float, n: int = 400, start: int = 3) -> np.ndarray:
    return base * np.arange(start, start + n, dtype=np.float64)


@given(st.sampled_from(BASES), st.sampled_from(["m", "ft"]), st.integers(2, 10), st.floats(-60, 60))
def test_higher_ranks_never_hide_before_lower_ones(base, units, index_every, lat):
    s = make_schedule(base, start_scale=50_000, latitude=lat, units=units, index_every=index_every,
                      elevations=levels_of(base))
    hide = [r.hide_zoom for r in s.ranks]
    fade = [r.fade_zoom for r in s.ranks]
    assert hide[-1] == fade[-1] == NEVER and s.ranks[-1].hide_scale is None  # the top rank never hides
    for r in range(len(s.ranks) - 1):
        assert fade[r] > hide[r]  # a fade range, not a pop
        assert hide[r] > hide[r + 1] or r + 1 == len(s.ranks) - 1  # the next rank goes later (smaller zoom)
        if r + 1 < len(s.ranks) - 1:
            assert fade[r + 1] == pytest.approx(hide[r])  # one rank fades at a time, with no gap


@given(st.sampled_from(BASES), st.integers(2, 10))
def test_every_level_of_the_base_interval_has_the_rank_of_its_coarsest_step(base, index_every):
    e = levels_of(base)
    s = make_schedule(base, start_scale=25_000, latitude=40, index_every=index_every, elevations=e)
    steps = s.steps
    assert steps[0] == base and steps[1] == pytest.approx(base * index_every)  # then the index contours
    for a, b in zip(steps, steps[1:], strict=False):
        q = b / a
        assert b > a and abs(q - round(q)) < 1e-9  # a chain: each step a multiple of the one before
    ranks = s.rank_of(e)
    assert ranks.min() == 0 and ranks.max() <= len(steps) - 1
    for elevation, r in zip(e.tolist(), ranks.tolist(), strict=True):
        q = elevation / steps[r]
        assert abs(q - round(q)) < 1e-6
        if r + 1 < len(steps):
            q = elevation / steps[r + 1]
            assert abs(q - round(q)) > 1e-6
    assert (s.level_of(e) == (ranks >= 1)).all()  # level 1 = index contours = rank >= 1


def test_visible_interval_grows_with_the_scale_denominator():
    """Ink ∝ 2^-z / interval: each rank is fully drawn down to the scale where the visible interval equals its
    step (interval ∝ scale denominator) and gone where it reaches the next step."""
    s = make_schedule(20.0, start_scale=50_000, latitude=36.6, elevations=levels_of(20.0, 200, 5))
    assert [r.step for r in s.ranks] == [20.0, 100.0, 200.0, 1000.0, 2000.0]
    for r in s.ranks[:-1]:
        assert r.fade_scale / r.step == pytest.approx(50_000 / 20.0)
        nxt = s.ranks[r.rank + 1].step
        assert r.hide_scale / nxt == pytest.approx(50_000 / 20.0)
        assert float(scale_for_zoom(r.hide_zoom, 36.6)) == pytest.approx(r.hide_scale, rel=1e-3)


def test_feet_follow_the_feet_series():
    s = make_schedule(40.0, start_scale=24_000, latitude=36.6, units="ft", elevations=levels_of(40.0, 300, 10))
    steps = [r.step for r in s.ranks]
    assert steps[:2] == [40.0, 200.0] and s.units == "ft"
    assert all(step in SERIES for step in steps[1:])
    assert steps == [40.0, 200.0, 1000.0, 2000.0, 10000.0][: len(steps)]


def test_the_chain_stops_where_coarser_steps_would_leave_no_line():
    s = make_schedule(20.0, start_scale=50_000, latitude=36.6, elevations=np.arange(220.0, 1000.0, 20.0))
    top = s.ranks[-1]
    assert top.step == 200.0 and np.count_nonzero(s.rank_of(np.arange(220.0, 1000.0, 20.0)) == top.rank) >= 2


def test_a_single_level_gets_one_rank_that_never_hides():
    s = make_schedule(None, start_scale=50_000, latitude=10)
    assert len(s.ranks) == 1 and s.ranks[0].hide_zoom == NEVER and s.rank_of([437.0]).tolist() == [0]


def test_override_table():
    s = make_schedule(10.0, start_scale=50_000, latitude=0, override="10:80000, 50:300000, 250")
    assert [(r.step, r.fade_scale, r.hide_scale) for r in s.ranks] == [
        (10.0, 50_000.0, 80_000.0), (50.0, 80_000.0, 300_000.0), (250.0, None, None)
    ]
    assert s.rank_of([10.0, 50.0, 500.0]).tolist() == [0, 1, 2]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "non-empty"),
        ("20:100000,30:200000,300", "entry 2 '30:200000': step must be a larger multiple of the previous step 20"),
        ("20:100000,100:90000,1000", "entry 2 '100:90000': hide scale must be larger than the previous one 100000"),
        ("20:abc,100", "entry 1 '20:abc': not a number"),
        ("20:100000,100:200000", "entry 2 '100:200000': expected STEP (the last entry, never hidden)"),
        ("20,100", "entry 1 '20': expected STEP:HIDE_SCALE"),
        ("20:-5,100", "entry 1 '20:-5': step and scale must be positive"),
    ],
)
def test_bad_override_tables_are_named(text, message):
    with pytest.raises(InvalidParameter, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_schedule(text)


def test_override_must_give_every_level_a_rank():
    with pytest.raises(InvalidParameter, match="step 50 must divide the data's interval 20 m"):
        make_schedule(20.0, start_scale=50_000, latitude=0, override="50:100000,100")


@pytest.mark.parametrize(("units", "index_every"), [("yards", 5), ("m", 1), ("m", 2.5)])
def test_bad_options_are_named(units, index_every):
    with pytest.raises(InvalidParameter, match="units" if units == "yards" else "index_every"):
        make_schedule(20.0, start_scale=50_000, latitude=0, units=units, index_every=index_every)


def test_zooms_are_at_the_given_latitude():
    a = make_schedule(20.0, start_scale=50_000, latitude=0, elevations=levels_of(20.0))
    b = make_schedule(20.0, start_scale=50_000, latitude=60, elevations=levels_of(20.0))
    # cos 60° = 1/2: the same scale is one zoom level further out at 60°.
    assert a.ranks[0].hide_zoom - b.ranks[0].hide_zoom == pytest.approx(1.0, abs=2e-4)
    assert not math.isnan(a.ranks[0].fade_zoom)


def test_an_override_must_keep_every_level_fully_drawn_at_the_source_scale():
    with pytest.raises(InvalidParameter, match="entry 1: hide scale 40000 must be larger than the source scale 50000"):
        make_schedule(20.0, start_scale=50_000, latitude=0, override="20:40000,100")
    assert make_schedule(20.0, start_scale=50_000, latitude=0, override="20:60000,100").ranks[0].fade_scale == 50_000


def test_check_schedule_fits_names_the_entry_and_passes_options_without_an_override():
    check_schedule_fits(None, 20.0, 50_000)
    check_schedule_fits(CartographyOptions(), 20.0, 50_000)
    check_schedule_fits(CartographyOptions(schedule="10:100000,100"), 20.0, 50_000)  # 10 divides 20
    with pytest.raises(InvalidParameter, match="schedule entry 1: step 30 must divide the data's interval 20 ft"):
        check_schedule_fits(CartographyOptions(units="ft", schedule="30:100000,300"), 20.0, 50_000)
