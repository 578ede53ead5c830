"""Wang–Müller (engine.baselines.wang_muller): bend detection, measures, operators and the ladder."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from engine.baselines import bend_count, ladder, simplify_at_scale
from engine.baselines._wm_kernels import bend_measures, detect_bends, turning_angles
from engine.baselines.wang_muller import DEFAULT_WM_PARAMS, WMParams, reference_size, wm_at_scale
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.tolerances import tolerance_for_scale
from engine.types import Contour

HYPOTHESIS = settings(deadline=None, max_examples=40)


def scale_for_diameter(d_m: float) -> float:
    """Map scale whose reference half circle has diameter ``d_m`` (D = 0.5 mm x scale)."""
    return d_m / 5e-4  # the reference half circle is 0.5 mm across on paper


def half_circle(x0: float, d: float, n: int = 24, up: bool = True) -> np.ndarray:
    """Vertices of a half circle over the x axis from (x0, 0) to (x0 + d, 0), both ends included."""
    theta = np.linspace(np.pi, 0.0, n)
    y = 0.5 * d * np.sin(theta) * (1.0 if up else -1.0)
    return np.column_stack([x0 + 0.5 * d + 0.5 * d * np.cos(theta), y])


def bumpy_line(small_d: float, large_d: float) -> np.ndarray:
    """A straight line along x with one small half-circle bump at x = 100 and one large one at x = 300."""
    return np.vstack(
        [[[0.0, 0.0]], half_circle(100.0, small_d), half_circle(300.0, large_d), [[500.0, 0.0]]]
    )


def as_geometry(xy: np.ndarray, closed: bool) -> shapely.Geometry:
    return shapely.LinearRing(xy) if closed else shapely.LineString(xy)


def noisy_contour(seed: int, n: int, closed: bool, wiggle: float) -> np.ndarray:
    """Seeded noisy star-shaped ring, or the open arc of one (both simple by construction).

    With a large ``wiggle`` the radii jump between neighbours: narrow spikes and bays whose baselines pass
    close to other parts of the line, the cases where an elimination could create a crossing.
    """
    rng = np.random.default_rng(seed)
    span = 2.0 * np.pi if closed else 1.7 * np.pi
    angle = np.sort(rng.uniform(0.0, span, n))
    radius = 300.0 * np.abs(1.0 + 0.3 * np.sin(4.0 * angle) + wiggle * rng.standard_normal(n)) + 1.0
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


def meander(seed: int, n: int, noise_m: float) -> np.ndarray:
    """A seeded meandering open line with noise (not always simple: callers filter)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 6.0 * np.pi, n)
    x = 100.0 * t + 60.0 * np.sin(t) + rng.normal(0.0, noise_m, n)
    y = 250.0 * np.sin(1.3 * t) + rng.normal(0.0, noise_m, n)
    return np.column_stack([x, y])


# --- bends -------------------------------------------------------------------------------------------------


def test_zigzag_line_has_one_bend_per_interior_vertex() -> None:
    xy = np.array([[float(i), float(i % 2)] for i in range(9)])
    start, length, sign = detect_bends(xy, False, math.radians(5.0))
    assert start.tolist() == list(range(1, 8))
    assert length.tolist() == [1] * 7
    assert sign.tolist() == [-1, 1, -1, 1, -1, 1, -1]


def test_star_ring_has_one_bend_per_vertex() -> None:
    k = 5
    angle = np.linspace(0.0, 2.0 * np.pi, 2 * k, endpoint=False)
    radius = np.where(np.arange(2 * k) % 2 == 0, 10.0, 4.0)
    star = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    assert bend_count(star, closed=True) == 2 * k


def test_bends_wrap_around_a_rings_seam() -> None:
    # A clockwise square with a U-shaped notch in its top edge; the notch's three vertices straddle index 0.
    ring = np.array(
        [[5.0, 6.5], [5.8, 7.0], [6.0, 10.0], [10.0, 10.0], [10.0, 0.0], [0.0, 0.0], [0.0, 10.0], [4.0, 10.0],
         [4.2, 7.0]]
    )
    start, length, sign = detect_bends(ring, True, math.radians(5.0))
    runs = sorted(sorted(int((s + j) % 9) for j in range(n)) for s, n in zip(start, length, strict=True))
    assert runs == [[0, 1, 8], [2, 3, 4, 5, 6, 7]]
    notch = [i for i, (s, n) in enumerate(zip(start, length, strict=True)) if n == 3][0]
    assert sign[notch] == 1 and sign[1 - notch] == -1


def test_convex_ring_and_straight_line() -> None:
    angle = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    assert bend_count(np.column_stack([np.cos(angle), np.sin(angle)]), closed=True) == 0
    assert bend_count(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]), closed=False) == 1
    c_shape = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 2.0], [0.0, 3.0]])
    assert bend_count(c_shape, closed=False) == 1


def polyline_from_turns(turns_deg: list[float], step_m: float = 10.0) -> np.ndarray:
    """A line of equal steps heading east that turns by the given angles at its interior vertices."""
    headings = np.radians(np.concatenate([[0.0], np.cumsum(turns_deg)]))
    steps = step_m * np.column_stack([np.cos(headings), np.sin(headings)])
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


@pytest.mark.parametrize(("wobble_deg", "bends"), [(2.0, 1), (4.9, 1), (5.1, 3), (20.0, 3)])
def test_gentle_inflection_merges_into_its_bend(wobble_deg: float, bends: int) -> None:
    # A right-turning arc with one vertex turning left in the middle: below 5 degrees it is a wobble.
    turns = [-15.0] * 6 + [wobble_deg] + [-15.0] * 6
    xy = polyline_from_turns(turns)
    assert np.degrees(turning_angles(xy, False))[1:-1] == pytest.approx(turns)
    assert bend_count(xy, closed=False) == bends


def test_gentle_run_counts_its_total_turning() -> None:
    # Three left turns of 3 degrees each (9 in total) are a real, if gentle, bend of their own.
    xy = polyline_from_turns([-15.0] * 6 + [3.0, 3.0, 3.0] + [-15.0] * 6)
    assert bend_count(xy, closed=False) == 3


def test_half_circle_measures() -> None:
    xy = np.vstack([[[-50.0, 0.0]], half_circle(0.0, 20.0, n=400), [[70.0, 0.0]]])
    start, length, _ = detect_bends(xy, False, math.radians(5.0))
    arc = int(np.argmax(length))
    area, perim, curv, base = bend_measures(xy, False, start[arc], length[arc], turning_angles(xy, False))
    assert area == pytest.approx(math.pi * 100.0 / 2.0, rel=1e-4)
    assert perim == pytest.approx(math.pi * 10.0 + 20.0, rel=1e-4)
    assert base == pytest.approx(20.0)
    assert curv == pytest.approx(math.pi / (math.pi * 10.0), rel=2e-2)
    cmp = 4.0 * math.pi * area / perim**2
    assert cmp == pytest.approx(2.0 * math.pi**2 / (math.pi + 2.0) ** 2, rel=1e-4)
    # The adjusted size of the reference half circle is almost its own area.
    assert 0.75 * area / cmp == pytest.approx(reference_size(20.0), rel=5e-3)


# --- operators ---------------------------------------------------------------------------------------------


def test_only_the_small_bend_is_eliminated() -> None:
    xy = bumpy_line(small_d=10.0, large_d=100.0)
    out = simplify_at_scale("wm", xy, False, scale_for_diameter(40.0))
    in_small = (out[:, 0] > 100.0) & (out[:, 0] < 110.0)
    assert not np.any(in_small), "the 10 m bump is below the 40 m reference and too small to exaggerate"
    large = xy[(xy[:, 0] >= 300.0) & (xy[:, 0] <= 400.0)]
    assert {tuple(p) for p in large} <= {tuple(p) for p in out}, "the 100 m bump stays as it is"
    # Below both sizes nothing changes.
    assert_array_equal(simplify_at_scale("wm", xy, False, scale_for_diameter(5.0)), xy)


def test_isolated_small_bend_is_exaggerated_to_the_reference_size() -> None:
    xy = bumpy_line(small_d=10.0, large_d=100.0)
    d_ref = 13.0
    out = simplify_at_scale("wm", xy, False, scale_for_diameter(d_ref))
    assert len(out) == len(xy), "exaggeration moves vertices, it does not remove them"
    bump = out[(out[:, 0] >= 100.0) & (out[:, 0] <= 110.0)]
    assert bump[:, 1].max() > 5.0 * 1.2, "the bump is stretched away from its baseline"
    assert bump[:, 1].max() < 5.0 * DEFAULT_WM_PARAMS.max_stretch + 1e-9
    start, length, _ = detect_bends(out, False, math.radians(5.0))
    ang = turning_angles(out, False)
    sizes = []
    for s, n in zip(start, length, strict=True):
        _, perim, _, _ = bend_measures(out, False, s, n, ang)
        sizes.append(0.75 * perim**2 / (4.0 * math.pi))
    assert min(sizes) >= reference_size(d_ref) * (1.0 - 1e-9)
    assert shapely.LineString(out).is_simple


def test_a_run_of_similar_small_bends_is_combined_not_erased() -> None:
    # Thirteen 2 m teeth on a straight line: each is below the 4 m reference. Combination joins the teeth
    # that point up into one wide bend instead of eliminating them all.
    teeth = np.array([[100.0 + i, 2.0 * (i % 2)] for i in range(15)])
    xy = np.vstack([[[0.0, 0.0]], teeth, [[214.0, 0.0]]])
    out = simplify_at_scale("wm", xy, False, scale_for_diameter(4.0))
    region = out[(out[:, 0] >= 100.0) & (out[:, 0] <= 114.0)]
    assert len(region) < len(teeth)
    assert region[:, 1].max() == 2.0, "the combined bend keeps the teeth's outer vertices"
    assert np.all(region[1:-1, 1] == 2.0), "one bend across the tops, no tooth left"
    assert shapely.LineString(out).is_simple


def hooked_line(with_hook: bool) -> np.ndarray:
    """A 4 m x 4 m square bump at x = 10..14 on a long straight line, and (optionally) the line's far end
    coming back underneath and poking up into the bump, through the bump's baseline."""
    xy = [[-100.0, 0.0], [10.0, 0.0], [10.0, 4.0], [14.0, 4.0], [14.0, 0.0], [100.0, 0.0], [100.0, -10.0],
          [12.0, -10.0]]
    if with_hook:
        xy.append([12.0, 2.0])
    return np.array(xy)


def test_elimination_that_would_cross_the_line_is_refused() -> None:
    # D = 10 m: the bump (adjusted size 15 m²) is below the reference (39 m²) and too small to exaggerate.
    scale = scale_for_diameter(10.0)
    free = hooked_line(with_hook=False)
    assert [10.0, 4.0] not in simplify_at_scale("wm", free, False, scale).tolist()
    hooked = hooked_line(with_hook=True)
    assert shapely.LineString(hooked).is_simple
    assert_array_equal(simplify_at_scale("wm", hooked, False, scale), hooked)
    for level in ladder("wm", hooked, False, levels=20):
        assert shapely.LineString(level).is_simple


@given(seed=st.integers(0, 100_000), closed=st.booleans(), wiggle=st.sampled_from([0.02, 0.1, 0.3]))
@HYPOTHESIS
def test_wm_never_creates_a_self_intersection(seed: int, closed: bool, wiggle: float) -> None:
    xy = noisy_contour(seed, 150, closed, wiggle)
    assert as_geometry(xy, closed).is_simple
    for scale in (5e4, 2e5, 1e6, 5e6):
        out = simplify_at_scale("wm", xy, closed, scale)
        assert as_geometry(out, closed).is_simple, scale
        assert len(out) >= (3 if closed else 2)
    for level in ladder("wm", xy, closed, levels=40):
        assert as_geometry(level, closed).is_simple


@given(seed=st.integers(0, 100_000), noise_m=st.sampled_from([1.0, 3.0, 5.0]))
@HYPOTHESIS
def test_wm_never_creates_a_self_intersection_on_meanders(seed: int, noise_m: float) -> None:
    xy = meander(seed, 200, noise_m)
    assume(shapely.LineString(xy).is_simple)
    for scale in (5e4, 2e5, 1e6, 5e6):
        assert shapely.LineString(simplify_at_scale("wm", xy, False, scale)).is_simple, scale
    for level in ladder("wm", xy, False, levels=40):
        assert shapely.LineString(level).is_simple


def test_wm_keeps_the_shared_noisy_fixtures_simple(
    noisy_open_line: Contour, noisy_ellipse_ring: Contour
) -> None:
    for contour in (noisy_open_line, noisy_ellipse_ring):
        for scale in (1e5, 5e5, 2e6):
            out = simplify_at_scale("wm", contour.coords, contour.closed, scale)
            assert as_geometry(out, contour.closed).is_simple


def test_self_touching_input_gets_no_new_contacts(self_touching_loop: Contour) -> None:
    xy = self_touching_loop.coords
    for scale in (1e5, 1e6, 1e7):
        out = simplify_at_scale("wm", xy, True, scale)
        assert len(out) >= 3
        assert {tuple(p) for p in out} <= {tuple(p) for p in xy}


def test_larger_reference_removes_more() -> None:
    xy = meander(5, 300, 2.0)
    counts = [len(simplify_at_scale("wm", xy, False, s)) for s in (1e4, 1e5, 1e6, 1e7, 1e8)]
    assert counts[0] > counts[-1]
    assert counts[-1] <= 10


# --- ladder ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ladder_reduces_bends_by_one_percent_per_level(seed: int) -> None:
    # An x-monotone line: a baseline can never cross the rest, so no elimination is refused.
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(5.0, 30.0, 200))
    xy = np.column_stack([x, np.cumsum(rng.normal(0.0, 10.0, 200))])
    b0 = bend_count(xy, False)
    levels = ladder("wm", xy, False, levels=100)
    for i, level in enumerate(levels[:-1]):
        target = math.floor(b0 * (1.0 - i / 99.0) + 0.5)
        assert bend_count(level, False) <= target, i
    assert bend_count(levels[-2], False) <= 1
    assert_array_equal(levels[-1], xy[[0, -1]])
    # The paper's point: bends drop steadily, the vertex count jumps.
    assert bend_count(levels[50], False) == pytest.approx(b0 / 2, abs=2)


def test_ring_ladder_ends_in_a_triangle_of_its_own_vertices() -> None:
    xy = noisy_contour(9, 120, True, 0.05)
    levels = ladder("wm", xy, True, levels=100)
    assert len(levels[-1]) == 3
    assert {tuple(p) for p in levels[-1]} <= {tuple(p) for p in levels[-2]}
    assert shapely.Polygon(levels[-1]).area > 0.0


def test_ladder_removes_the_smallest_bend_first() -> None:
    xy = bumpy_line(small_d=10.0, large_d=100.0)
    b0 = bend_count(xy, False)
    levels = ladder("wm", xy, False, levels=b0 + 2)
    first_change = next(level for level in levels if len(level) < len(xy))
    assert not np.any((first_change[:, 0] > 100.0) & (first_change[:, 0] < 110.0))
    assert np.all(np.isin(xy[(xy[:, 0] > 300.0) & (xy[:, 0] < 400.0)], first_change))


@pytest.mark.slow
def test_wm_keeps_the_jacksboro_contours_simple() -> None:
    # Real DEM contours (the bundled sample): without the crossing check, about 55 of these 269 contours
    # get a self-intersecting ladder level or at-scale result.
    contours = [c for c in read_source(sample_contours_path()).contours if c.n_vertices >= 100]
    assert len(contours) > 200
    for contour in contours:
        if not as_geometry(contour.coords, contour.closed).is_simple:
            continue
        for scale in (1e5, 5e5, 2e6, 1e7):
            out = simplify_at_scale("wm", contour.coords, contour.closed, scale)
            assert as_geometry(out, contour.closed).is_simple, (contour.id, scale)
        for i, level in enumerate(ladder("wm", contour.coords, contour.closed)):
            assert as_geometry(level, contour.closed).is_simple, (contour.id, i)


def test_reference_diameter_is_0_5_mm_on_paper_by_default() -> None:
    # 0.5 mm: five times DP's epsilon, the smallest closed shape a map can show.
    assert DEFAULT_WM_PARAMS.diameter_on_paper_m * 250_000 == pytest.approx(5 * tolerance_for_scale(250_000))
    xy = meander(3, 300, 2.0)
    narrower = WMParams(diameter_on_paper_m=0.0001)
    assert_array_equal(wm_at_scale(xy, False, 200_000, narrower), simplify_at_scale("wm", xy, False, 40_000))
