"""The one contour-interval rule (engine.intervals.infer_interval): a robust greatest common divisor of the
differences between levels, on the cases real contour sets bring (ties, missing levels, noise, bathymetry)."""

from __future__ import annotations

import json
import math
from functools import reduce
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.intervals import MAX_DIVISOR, infer_interval
from engine.io.source import read_source, sample_contours_path


def sample_levels() -> list[float]:
    features = json.loads(sample_contours_path().read_text())["features"]
    return [float(f["properties"]["elevation"]) for f in features]


@pytest.mark.parametrize(
    ("levels", "interval"),
    [
        ([0.0, 20.0, 30.0], 10.0),  # a tie of steps 20 and 10: 10 holds every level, 20 leaves 30 off
        ([0.0, 20.0, 40.0, 50.0, 60.0], 10.0),  # 20 is the most common step, yet 50 is on no 20 m grid
        ([0.0, 20.0, 80.0, 100.0], 20.0),  # missing levels leave the interval
        ([0.0, 19.999, 40.001, 60.0, 80.0], 20.0),  # float noise: the grid fitted through the levels
        ([0.0, 20.0, 20.001, 40.0, 39.998, 60.0], 20.0),  # one level written twice, a hair apart
        ([float(e) for e in range(-200, 1, 20)], 20.0),  # bathymetry
        ([-35.0, -15.0, 5.0, 25.0], 20.0),  # levels off zero by an offset
        ([0.0, 40.0, 80.0, 120.0], 40.0),  # every other 20 m level: nothing shows the finer grid
        ([0.0, 20.0, 33.0], 13.0),  # on no grid within a tenth of the smallest step: the most common step
        ([round(6.096 * k, 1) for k in range(20)], 6.1),  # 20 ft in metres rounded to 0.1: steps 6.1 and 6.0
    ],
)
def test_the_interval_is_the_largest_step_every_level_is_on(levels: list[float], interval: float) -> None:
    assert infer_interval(levels) == pytest.approx(interval, abs=1e-9)


@pytest.mark.parametrize("levels", [[], [100.0], [100.0, 100.0], [100.0, 100.0000001]])
def test_one_level_has_no_interval(levels: list[float]) -> None:
    assert infer_interval(levels) is None


def test_the_bundled_sample_and_its_damaged_copies_keep_their_20_m_interval() -> None:
    levels = sample_levels()
    assert infer_interval(levels) == 20.0
    assert infer_interval([e for e in levels if e != 600.0]) == 20.0  # one level missing
    assert infer_interval([e for e in levels if e <= 800.0 or e % 100.0 == 0.0]) == 20.0  # index only, above 800


def test_the_build_records_the_interval_the_renderer_infers(tmp_path: Path) -> None:
    """The reader's interval (stored with the dataset) is the one rule's: levels 0, 20, 30 give 10, not 20."""
    features = [
        {
            "type": "Feature",
            "properties": {"elevation": e},
            "geometry": {"type": "LineString", "coordinates": [[-84.2, 36.5 + e / 1e4], [-84.1, 36.5 + e / 1e4]]},
        }
        for e in (0.0, 20.0, 30.0)
    ]
    path = tmp_path / "tie.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    cs = read_source(path)
    assert cs.interval == infer_interval([c.elevation for c in cs.contours]) == 10.0


@settings(max_examples=300, deadline=None)
@given(
    interval=st.sampled_from([0.1, 0.5, 1.0, 2.0, 2.5, 5.0, 10.0, 20.0, 25.0, 50.0, 100.0]) | st.floats(0.1, 500.0),
    offset=st.floats(-1000.0, 1000.0),
    ks=st.sets(st.integers(-20, 19), min_size=2, max_size=40).map(sorted),
    data=st.data(),
)
def test_levels_drawn_on_a_grid_give_its_interval_or_a_multiple(
    interval: float, offset: float, ks: list[int], data: st.DataObject
) -> None:
    """Levels k * interval + offset for a subset of k, each with noise up to 1e-3 interval, a third of them
    written twice: the inferred interval is g * interval, g the greatest common divisor of the differences of k
    (interval itself unless the subset skips levels regularly), as long as the smallest difference is at most
    MAX_DIVISOR times g; otherwise the most common step, still a whole multiple of interval."""
    noise = st.floats(-1e-3, 1e-3)
    levels = [k * interval + offset + data.draw(noise) * interval for k in ks]
    twice = data.draw(st.lists(st.sampled_from(ks), max_size=len(ks) // 3))
    levels += [k * interval + offset + data.draw(noise) * interval for k in twice]
    inferred = infer_interval(levels)
    assert inferred is not None
    gaps = [b - a for a, b in zip(ks, ks[1:], strict=False)]
    g = reduce(math.gcd, gaps)
    if min(gaps) // g <= MAX_DIVISOR:
        assert inferred == pytest.approx(g * interval, rel=3e-3)  # two levels' noise over one step at worst
    else:
        multiple = inferred / interval
        assert round(multiple) >= 1 and abs(multiple - round(multiple)) < 1e-2
        assert round(multiple) % g == 0
