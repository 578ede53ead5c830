"""Label anchors (issue 11, docs/design.md section 9.3) and the tile-zoom rule of the schedule."""

import math

import mapbox_vector_tile
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.cartography.dataset import DatasetCartography
from engine.cartography.labels import (
    LabelSource,
    LabelStyle,
    metres_per_px,
    place_labels,
    spaced_along,
    upright_angle,
)
from engine.cartography.options import CartographyOptions
from engine.cartography.schedule import make_schedule
from engine.tiles.mvt import encode_line_tile, encode_point_tile
from engine.tiles.scale import scale_for_zoom

LADDER = np.geomspace(50_000, 500_000, 33)


def still_source(fid, xy, *, text="500 m", rank=1, first_zoom=12.0, top=None):
    """A contour whose t is 0 at every scale unless a top row is given (then t = 1 everywhere)."""
    xy = np.asarray(xy, dtype=float)
    table = np.zeros(len(LADDER)) if top is None else np.ones(len(LADDER))
    return LabelSource(fid, 500.0, text, rank, xy, xy if top is None else np.asarray(top, float), table, first_zoom)


def straight_line(y, x0=0.0, length=20_000.0, n=200):
    return np.column_stack([np.linspace(x0, x0 + length, n), np.full(n, y)])


def overlaps_at_first_common_zoom(labels):
    n = len(labels)
    bad = []
    for i in range(n):
        for j in range(i + 1, n):
            mpp = float(metres_per_px(max(labels.min_zoom[i], labels.min_zoom[j])))
            half = (labels.box_px[i] + labels.box_px[j]) / 2 * mpp
            d = np.abs(labels.xy[i] - labels.xy[j])
            if d[0] < half[0] and d[1] < half[1]:
                bad.append((i, j))
    return bad


def test_no_two_label_boxes_overlap_at_the_zoom_they_first_show_together():
    # 30 parallel straight lines 40 m apart: at zoom 12 (38 m/px) their labels would sit on top of each other.
    sources = [still_source(k, straight_line(40.0 * k), first_zoom=12.0 + (k % 3)) for k in range(30)]
    labels = place_labels(sources, LADDER, 36.6, 16.0)
    assert len(labels) > 0
    assert overlaps_at_first_common_zoom(labels) == []
    assert len(set(labels.fid.tolist())) < 30  # some had to give way: the test is not vacuous


def test_long_lines_get_spaced_labels_and_short_ones_only_where_a_label_fits():
    style = LabelStyle()
    long_line = still_source(1, straight_line(0.0, length=100_000.0, n=1000), first_zoom=12.0)
    short = still_source(2, straight_line(50_000.0, length=500.0, n=10), first_zoom=12.0)  # < one label long
    labels = place_labels([long_line, short], LADDER, 36.6, 16.0, style)
    on_long = labels.fid == 1
    order = np.argsort(labels.xy[on_long][:, 0])
    xs, zs = labels.xy[on_long][order, 0], labels.min_zoom[on_long][order]
    assert len(xs) >= 3
    (z_short,) = labels.min_zoom[labels.fid == 2]  # the short line is labelled once the label fits on it
    label_px = style.char_px * len("500 m") + 2 * style.padding_px
    assert z_short > 12.0 and label_px * float(metres_per_px(z_short)) <= 500.0
    # Spaced by spacing_px at the zoom both neighbours show.
    assert (np.diff(xs) >= style.spacing_px * metres_per_px(np.maximum(zs[1:], zs[:-1])) - 1e-6).all()


def test_labels_sit_on_the_straight_part_and_run_along_it():
    # A line running north-east, then a tight zigzag: labels only on the straight part, rotated along it.
    t = np.linspace(0, 1, 300)[:, None]
    straight = t * np.array([[20_000.0, 20_000.0]])
    zig = np.column_stack([20_000 + np.arange(1, 200) * 100.0, 20_000 + 300.0 * (np.arange(1, 200) % 2)])
    labels = place_labels([still_source(1, np.vstack([straight, zig]), first_zoom=12.0)], LADDER, 36.6, 16.0)
    assert len(labels) >= 1
    assert (labels.xy[:, 0] <= 20_000.0).all()  # none on the zigzag
    assert labels.angle == pytest.approx(np.full(len(labels), -45.0), abs=0.5)  # text rises to the east


def test_labels_avoid_places_where_the_line_moves_while_it_morphs():
    base = straight_line(0.0, length=40_000.0, n=400)
    top = base.copy()
    top[:200, 1] += 500.0  # the western half moves by 500 m between t = 0 and t = 1 (13 px at zoom 12)
    labels = place_labels([still_source(1, base, top=top, first_zoom=12.0)], LADDER, 36.6, 16.0)
    assert len(labels) >= 1 and (labels.xy[:, 0] > base[199, 0]).all()


def test_upright_angles_stay_within_plus_minus_90():
    a = np.radians(np.arange(0, 360, 7.5))
    angle = upright_angle(np.cos(a), np.sin(a))
    assert angle.min() >= -90 and angle.max() <= 90
    # A direction and its reverse give the same upright text.
    assert upright_angle(np.array([2.0]), np.array([1.0])) == pytest.approx(
        upright_angle(np.array([-2.0]), np.array([-1.0]))
    )


def test_tile_of_zoom_z_holds_a_rank_iff_its_hide_zoom_is_below_z_plus_1():
    # hide scales at zoom exactly 10 and at zoom 8.5 on the equator.
    s10, s85 = (float(scale_for_zoom(z, 0.0)) for z in (10.0, 8.5))
    schedule = make_schedule(20.0, start_scale=50_000, latitude=0.0, override=f"20:{s10},100:{s85},200")
    assert [r.hide_zoom for r in schedule.ranks] == [10.0, 8.5, -1.0]
    carto = DatasetCartography(CartographyOptions(units="m"), schedule, 0.0, 12.0)
    e = np.array([20.0, 100.0, 200.0])
    assert carto.shown_in_tile(e, 10).tolist() == [True, True, True]
    assert carto.shown_in_tile(e, 9).tolist() == [False, True, True]  # hide_zoom 10 = 9 + 1: not in z9
    assert carto.shown_in_tile(e, 8).tolist() == [False, True, True]  # 8.5 < 9: visible at 8.5..9
    assert carto.shown_in_tile(e, 7).tolist() == [False, False, True]
    assert carto.shown_in_tile(e, 0).tolist() == [False, False, True]  # the top rank never hides


def test_integer_columns_and_points_encode_as_the_reference_decodes_them():
    pts = np.array([[0, 0], [10, 5], [3, 3], [7, 9]], dtype=np.int64)
    cols = {
        "elevation": [500.0, 520.0],
        "level": [1, 0],
        "rank": [2, 0],
        "index": [True, False],
        "hide_zoom": [-1.0, 9.5],
    }
    tile = mapbox_vector_tile.decode(
        encode_line_tile("contours", [1, 2], cols, pts, np.array([2, 2]), np.array([1, 1])),
        default_options={"y_coord_down": True},
    )
    props = [f["properties"] for f in tile["contours"]["features"]]
    assert props == [
        {"elevation": 500.0, "level": 1, "rank": 2, "index": True, "hide_zoom": -1.0},
        {"elevation": 520.0, "level": 0, "rank": 0, "index": False, "hide_zoom": 9.5},
    ]
    assert all(type(p["level"]) is int for p in props)
    labels = mapbox_vector_tile.decode(
        encode_point_tile(
            "contour_labels", [4], {"label": ["600 ft"], "angle": [-12.5], "rank": [1]}, np.array([[5, 4095]])
        ),
        default_options={"y_coord_down": True},
    )["contour_labels"]["features"]
    assert labels == [
        {
            "geometry": {"type": "Point", "coordinates": [5, 4095]},
            "properties": {"label": "600 ft", "angle": -12.5, "rank": 1},
            "id": 4,
            "type": "Feature",
        }
    ]
    assert not math.isnan(labels[0]["properties"]["angle"])


def _kept_by_testing_every_kept_label(xy, box, zoom, order) -> list[int]:  # noqa: ANN001 - arrays
    """The reference: each label in ``order`` tested against every label kept before it."""
    reference: list[int] = []
    for j in order.tolist():
        if reference:
            k = np.array(reference)
            half = (box[j] + box[k]) / 2 * metres_per_px(np.maximum(zoom[j], zoom[k]))[:, None]
            if (np.abs(xy[k] - xy[j]) < half).all(axis=1).any():
                continue
        reference.append(j)
    return reference


def test_label_placement_by_grid_keeps_exactly_the_labels_a_test_against_every_kept_label_keeps():
    """Issue 12: placement files kept labels in a grid instead of testing each against all (quadratic, an hour on
    a big dataset); the labels kept must be the same. The reference tests every kept label."""
    from engine.cartography.labels import _keep_apart

    rng = np.random.default_rng(3)
    n = 3_000
    xy = rng.uniform(0, 200_000, (n, 2))
    box = np.column_stack([rng.uniform(30, 160, n), rng.uniform(14, 40, n)])
    zoom = np.round(rng.uniform(7, 15, n), 1)  # ties on purpose
    order = np.lexsort((rng.uniform(size=n), zoom))
    kept = _keep_apart(xy, box, zoom, order)
    assert 200 < len(kept) < n  # some kept, some dropped: the test means something
    assert kept == _kept_by_testing_every_kept_label(xy, box, zoom, order)


@settings(max_examples=150, deadline=None)
@given(
    labels=st.lists(
        st.tuples(
            st.sampled_from([-2e7, -1e5, -3.0, 0.0, 7.5, 1e3, 4e4, 2e7]) | st.floats(-2e7, 2e7),  # x
            st.sampled_from([-2e7, -1e5, 0.0, 7.5, 1e3, 4e4]) | st.floats(-2e7, 2e7),  # y
            st.floats(1.0, 400.0),  # box width, px
            st.floats(1.0, 80.0),  # box height, px
            st.sampled_from([0.0, 5.0, 12.0, 12.5, 16.0]) | st.floats(0.0, 22.0),  # first zoom
        ),
        min_size=1,
        max_size=120,
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_compiled_placement_keeps_the_labels_every_kept_label_test_keeps(labels, seed) -> None:
    """The walk is compiled (issue 26: it runs serially in the build process): on labels drawn anywhere on the
    map, on top of one another, with tied zooms and boxes of any size, it keeps exactly what testing every kept
    label keeps."""
    from engine.cartography.labels import _keep_apart

    table = np.array(labels, dtype=np.float64)
    xy, box, zoom = table[:, :2], table[:, 2:4], table[:, 4]
    order = np.lexsort((np.random.default_rng(seed).uniform(size=len(table)), zoom))
    assert _keep_apart(xy, box, zoom, order) == _kept_by_testing_every_kept_label(xy, box, zoom, order)


def test_labels_placed_from_sources_read_once_in_a_stream_are_those_placed_from_a_list():
    """The build places labels from contours loaded a batch at a time (a generator, read once): the same
    anchors as from the whole list."""
    sources = [still_source(k, straight_line(40.0 * k), first_zoom=12.0 + (k % 3)) for k in range(30)]
    from_list = place_labels(sources, LADDER, 36.6, 16.0)
    streamed = place_labels((s for s in sources), LADDER, 36.6, 16.0)
    assert streamed.fid.tolist() == from_list.fid.tolist() and len(streamed) > 0
    np.testing.assert_array_equal(streamed.xy, from_list.xy)
    assert streamed.text == from_list.text and streamed.elevation.tolist() == from_list.elevation.tolist()


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0.0, 5_000.0, allow_nan=False),  # metres along the line
            st.integers(0, 64),  # first zoom, in quarter zooms from z10
            st.floats(0.5, 1.0),  # straightness
        ),
        max_size=60,
    ),
    st.sampled_from([0.0, 50.0, 600.0]),
)
def test_labels_along_a_line_are_spaced_as_by_testing_every_pair(candidates, spacing_px) -> None:
    # The greedy spacing of one contour's labels looks only at the nearest taken labels; it must take exactly
    # what testing each candidate against every taken one, at the later of their first zooms, takes.
    at = np.array([c[0] for c in candidates], dtype=np.float64)
    first = 10.0 + np.array([c[1] for c in candidates], dtype=np.float64) / 4
    score = np.array([c[2] for c in candidates], dtype=np.float64)
    spacing = spacing_px * metres_per_px(first)
    expected = np.zeros(len(at), dtype=bool)
    for j in sorted(range(len(at)), key=lambda k: (first[k], -score[k])):
        both_show = np.maximum(first[expected], first[j])
        if not (np.abs(at[expected] - at[j]) < spacing_px * metres_per_px(both_show)).any():
            expected[j] = True
    assert spaced_along(at, first, score, spacing).tolist() == expected.tolist()


def numpy_straightness(line: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """A line's straightness under a label window at every row, as whole-array NumPy (the rule stated plainly):
    chord / arc over ``width`` metres centred at the row, ends clamped and interpolated; window wholly inside."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    inside = (s - width / 2 >= 0) & (s + width / 2 <= s[-1])
    a = np.clip(s - width / 2, 0.0, s[-1])
    b = np.clip(s + width / 2, 0.0, s[-1])
    pa = np.column_stack([np.interp(a, s, line[:, 0]), np.interp(a, s, line[:, 1])])
    pb = np.column_stack([np.interp(b, s, line[:, 0]), np.interp(b, s, line[:, 1])])
    return np.hypot(*(pb - pa).T) / np.maximum(b - a, 1e-9), inside


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rows=st.integers(2, 60),
    zooms=st.integers(1, 12),
    repeats=st.lists(st.integers(0, 59), max_size=4),
    at_utm=st.booleans(),
)
def test_the_compiled_straightness_is_the_numpy_arithmetic_bit_for_bit(seed, rows, zooms, repeats, at_utm) -> None:
    from engine.cartography.label_lines import straightness_at_zooms

    rng = np.random.default_rng(seed)
    base = np.cumsum(rng.normal(0.0, 40.0, (rows, 2)), axis=0) + ([500_000.0, 4_000_000.0] if at_utm else 0.0)
    top = base + rng.normal(0.0, 5.0, (rows, 2))
    for i in repeats:  # rows of no length between them, as a line with repeated samples has
        if 0 < i < rows:
            base[i], top[i] = base[i - 1], top[i - 1]
    ts = np.sort(rng.uniform(0.0, 1.0, zooms))
    ts[0] = rng.choice([0.0, ts[0]])
    widths = rng.uniform(0.0, 3.0, zooms) * float(np.hypot(*np.ptp(base, axis=0)) + 1.0)
    widths[rng.random(zooms) < 0.2] = 0.0  # a window of no length: its ends fall on the rows themselves
    ratio, inside = straightness_at_zooms(base, top, ts, widths)
    for k in range(zooms):
        want_ratio, want_inside = numpy_straightness((1 - ts[k]) * base + ts[k] * top, float(widths[k]))
        assert np.array_equal(ratio[k], want_ratio)
        assert np.array_equal(inside[k], want_inside)
