"""Tests of engine.ccsm.ccs: the CCS of one contour, its slices and its Sim(t) table."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from engine.ccsm.ccs import build_ccs, build_surface, check_contour, slice_area
from engine.errors import InvalidContour
from engine.geom.douglas_peucker import douglas_peucker
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.params import BuildParams
from engine.types import Contour

DEFAULT = BuildParams()
TS = [0.0, 0.1, 0.35, 0.5, 0.8, 1.0]
CONTOURS = ["noisy_ellipse_ring", "noisy_open_line", "circle_ring", "self_touching_loop"]


def as_line(coords: np.ndarray, closed: bool) -> shapely.LineString:
    return shapely.LineString(np.vstack([coords, coords[:1]]) if closed else coords)


def signed_area(path: np.ndarray) -> float:
    """Shoelace area of a closed path (first point repeated), positive when counter-clockwise."""
    x, y = path[:, 0] - path[0, 0], path[:, 1] - path[0, 1]
    return float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]) / 2.0)


@pytest.mark.parametrize("name", CONTOURS)
def test_slice_at_zero_is_the_initial_contour(name: str, request: pytest.FixtureRequest) -> None:
    contour: Contour = request.getfixturevalue(name)
    ccs = build_ccs(contour, DEFAULT)
    distance = shapely.hausdorff_distance(
        shapely.LineString(ccs.at(0.0)), as_line(contour.coords, contour.closed)
    )
    assert distance < 1e-6


@pytest.mark.parametrize("name", CONTOURS)
def test_similarity_at_zero_is_one(name: str, request: pytest.FixtureRequest) -> None:
    ccs = build_ccs(request.getfixturevalue(name), DEFAULT)
    assert ccs.sim_t[0] == 0.0
    assert ccs.sim[0] == pytest.approx(1.0, abs=1e-9)
    assert ccs.similarity_at(0.0) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name", CONTOURS)
def test_slice_at_one_is_the_douglas_peucker_target(name: str, request: pytest.FixtureRequest) -> None:
    contour: Contour = request.getfixturevalue(name)
    ccs = build_ccs(contour, DEFAULT)
    keep = douglas_peucker(
        contour.coords, 0.0001 * DEFAULT.target_scale, contour.closed
    )  # 0.1 mm x 1:500,000
    target = as_line(contour.coords[keep], contour.closed)
    assert shapely.hausdorff_distance(shapely.LineString(ccs.at(1.0)), target) < 1e-6
    assert ccs.target_vertices == len(keep)


@pytest.mark.parametrize("t", TS)
def test_open_line_keeps_both_end_points_fixed(t: float, noisy_open_line: Contour) -> None:
    sliced = build_ccs(noisy_open_line, DEFAULT).at(t)
    assert_allclose(sliced[0], noisy_open_line.coords[0], rtol=0, atol=1e-6)
    assert_allclose(sliced[-1], noisy_open_line.coords[-1], rtol=0, atol=1e-6)


@pytest.mark.parametrize("reverse", [False, True])
def test_ring_slices_keep_the_initial_orientation(reverse: bool, noisy_ellipse_ring: Contour) -> None:
    coords = noisy_ellipse_ring.coords[::-1] if reverse else noisy_ellipse_ring.coords
    contour = Contour("ellipse", 1.0, coords.copy(), closed=True)
    expected = np.sign(signed_area(np.vstack([coords, coords[:1]])))
    ccs = build_ccs(contour, DEFAULT)
    for t in TS:
        assert np.sign(signed_area(ccs.at(t))) == expected


def test_open_line_keeps_its_direction(noisy_open_line: Contour) -> None:
    ccs = build_ccs(noisy_open_line, DEFAULT)
    for t in TS:
        assert_allclose(ccs.at(t)[0], noisy_open_line.coords[0], rtol=0, atol=1e-6)


def test_extreme_mode_gives_a_two_point_target_for_a_line(noisy_open_line: Contour) -> None:
    ccs = build_ccs(noisy_open_line, BuildParams(target_mode="extreme"))
    assert ccs.target_vertices == 2
    chord = shapely.LineString(noisy_open_line.coords[[0, -1]])
    assert shapely.hausdorff_distance(shapely.LineString(ccs.at(1.0)), chord) < 1e-6


def test_extreme_mode_gives_a_triangle_for_a_ring(noisy_ellipse_ring: Contour) -> None:
    ccs = build_ccs(noisy_ellipse_ring, BuildParams(target_mode="extreme"))
    assert ccs.target_vertices == 3
    top = shapely.Polygon(ccs.at(1.0))
    simplified = top.simplify(1e-6, preserve_topology=False)
    assert len(simplified.exterior.coords) - 1 == 3
    assert top.area > 0.1 * shapely.Polygon(noisy_ellipse_ring.coords).area


def test_points_mode_keeps_the_requested_vertex_count(noisy_open_line: Contour) -> None:
    ccs = build_ccs(noisy_open_line, BuildParams(target_mode="points", target_points=7))
    assert ccs.target_vertices == 7


def test_similarity_table_starts_at_one_and_does_not_increase(noisy_ellipse_ring: Contour) -> None:
    ccs = build_ccs(noisy_ellipse_ring, DEFAULT)
    assert len(ccs.sim) == DEFAULT.similarity_levels
    assert_allclose(ccs.sim_t, np.linspace(0.0, 1.0, DEFAULT.similarity_levels), atol=1e-15)
    assert ccs.sim[0] == pytest.approx(1.0, abs=1e-9)
    assert np.all(np.diff(ccs.sim) <= 1e-3)
    assert ccs.sim[-1] < ccs.sim[0]


@pytest.mark.parametrize("name", CONTOURS)
def test_same_scale_rule_slice_at_source_scale_is_within_5_m(
    name: str, request: pytest.FixtureRequest
) -> None:
    contour: Contour = request.getfixturevalue(name)
    ccs = build_ccs(contour, DEFAULT)
    tolerance = 0.0001 * DEFAULT.source_scale  # 0.1 mm at 1:50,000 = 5 m
    assert (
        shapely.hausdorff_distance(shapely.LineString(ccs.at(0.0)), as_line(contour.coords, contour.closed))
        <= tolerance
    )


def test_build_surface_starts_a_ring_at_a_characteristic_point(noisy_ellipse_ring: Contour) -> None:
    parts = build_surface(noisy_ellipse_ring, DEFAULT)
    assert parts.characteristic[0] == 0
    assert parts.characteristic[-1] == len(parts.path) - 1
    assert_allclose(parts.path[0], parts.path[-1], atol=0)
    assert_allclose(parts.initial[0], parts.target[0], atol=1e-9)


def test_ccs_records_the_contour_facts(noisy_ellipse_ring: Contour) -> None:
    ccs = build_ccs(noisy_ellipse_ring, DEFAULT)
    assert ccs.contour_id == "ellipse" and ccs.elevation == 120.0 and ccs.closed
    assert ccs.n_input_vertices == len(noisy_ellipse_ring.coords)
    assert ccs.length_m == pytest.approx(shapely.LinearRing(noisy_ellipse_ring.coords).length, rel=1e-12)
    minx, miny, maxx, maxy = ccs.bounds
    for t in TS:
        sliced = ccs.at(t)
        assert sliced[:, 0].min() >= minx - 1e-6 and sliced[:, 0].max() <= maxx + 1e-6
        assert sliced[:, 1].min() >= miny - 1e-6 and sliced[:, 1].max() <= maxy + 1e-6


def test_slice_area_of_a_ring_at_zero_is_its_area(circle_ring: Contour) -> None:
    ccs = build_ccs(circle_ring, DEFAULT)
    # rel 1e-6: the shoelace at UTM-sized coordinates loses about 1e-8 of the area to cancellation.
    assert slice_area(ccs, 0.0) == pytest.approx(shapely.Polygon(circle_ring.coords).area, rel=1e-6)


def test_slice_area_of_an_open_line_is_zero(noisy_open_line: Contour) -> None:
    assert slice_area(build_ccs(noisy_open_line, DEFAULT), 0.5) == 0.0


def test_tiny_ring_builds_with_a_finer_spacing(tiny_ring: Contour) -> None:
    ccs = build_ccs(tiny_ring, DEFAULT)
    distance = shapely.hausdorff_distance(shapely.LineString(ccs.at(0.0)), as_line(tiny_ring.coords, True))
    assert distance < 1e-6


BAD = [
    pytest.param(np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, 0.0]]), False, "NaN", id="nan"),
    pytest.param(np.array([[0.0, 0.0], [np.inf, 1.0], [2.0, 0.0]]), False, "NaN", id="inf"),
    pytest.param(np.array([[0.0, 0.0]]), False, "vertices", id="one-vertex-line"),
    pytest.param(np.array([[0.0, 0.0], [1.0, 0.0]]), True, "vertices", id="two-vertex-ring"),
    pytest.param(
        np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 1.0]]), False, "repeated", id="repeated"
    ),
    pytest.param(
        np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]]), True, "repeated", id="ring-repeats-first"
    ),
    pytest.param(np.array([[3.0, 3.0], [3.0, 3.0]]), False, "", id="zero-length"),
    pytest.param(np.zeros((3, 3)), False, "shape", id="bad-shape"),
]


@pytest.mark.parametrize(("coords", "closed", "why"), BAD)
def test_invalid_contour_raises_naming_its_id(coords: np.ndarray, closed: bool, why: str) -> None:
    contour = Contour(id="feature-42", elevation=0.0, coords=coords, closed=closed)
    with pytest.raises(InvalidContour, match="feature-42") as info:
        build_ccs(contour, DEFAULT)
    assert why in str(info.value)


def contour_fault_by_numpy(xy: np.ndarray, closed: bool) -> str:
    """check_contour's rule stated with NumPy: the first of NaN, too few vertices, a repeated step, no length."""
    if not np.all(np.isfinite(xy)):
        return "NaN"
    if len(xy) < (3 if closed else 2):
        return "vertices"
    steps = np.diff(np.concatenate([xy, xy[:1]]) if closed else xy, axis=0)
    if np.any(np.all(steps == 0, axis=1)):
        return "repeated"
    if np.hypot(steps[:, 0], steps[:, 1]).sum() <= 0:
        return "zero length"
    return "fine"


@settings(max_examples=300, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(0, 12),
    closed=st.booleans(),
    repeat=st.lists(st.integers(0, 11), max_size=2),
    bad=st.sampled_from([None, np.nan, np.inf, -np.inf]),
    tiny=st.booleans(),
)
def test_check_contour_refuses_what_the_numpy_rule_refuses(seed, n, closed, repeat, bad, tiny) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    xy = rng.integers(0, 3, (n, 2)).astype(float) * (1e-320 if tiny else 1.0) + 500_000.0 * (not tiny)
    for i in repeat:
        if 0 < i < n:
            xy[i] = xy[i - 1]
    if bad is not None and n:
        xy[rng.integers(0, n), rng.integers(0, 2)] = bad
    want = contour_fault_by_numpy(xy, closed)
    if want == "fine":
        check_contour(Contour("c", 0.0, xy, closed))
        return
    with pytest.raises(InvalidContour, match=want):
        check_contour(Contour("c", 0.0, xy, closed))


def test_check_contour_accepts_a_valid_contour(noisy_open_line: Contour) -> None:
    check_contour(noisy_open_line)  # no exception


def test_at_rejects_t_outside_the_unit_interval(circle_ring: Contour) -> None:
    ccs = build_ccs(circle_ring, DEFAULT)
    with pytest.raises(ValueError):
        ccs.at(1.5)


@pytest.fixture(scope="module")
def sample_contours() -> list[Contour]:
    """Every 25th contour of the bundled sample: rings of a few vertices to lines of thousands."""
    return read_source(sample_contours_path()).contours[::25]


@pytest.mark.parametrize("factor", [1.0, 0.25, 0.0])
def test_rows_are_the_fitted_surface_at_its_data_parameters_on_the_sample(
    factor: float, sample_contours: list[Contour]
) -> None:
    # The build takes the rows from the samples without a spline solve; the fitted surface passes there too.
    # (Measured: at most 2.3e-6 m apart on 3,815 short rings, the spline solve's rounding at UTM coordinates.)
    assert any(c.closed for c in sample_contours) and not all(c.closed for c in sample_contours)
    for contour in sample_contours:
        ccs = build_ccs(contour, DEFAULT, factor)
        surface = build_surface(contour, DEFAULT, factor).surface
        assert_allclose(ccs.base, surface.base(surface.params), rtol=0, atol=1e-5)
        assert_allclose(ccs.top, surface.top(surface.params), rtol=0, atol=1e-5)


def test_finer_tessellation_adds_rows_on_the_surface_between_samples(noisy_ellipse_ring: Contour) -> None:
    parts = build_surface(noisy_ellipse_ring, DEFAULT)
    ccs = build_ccs(noisy_ellipse_ring, BuildParams(tessellation_per_span=2))
    assert len(ccs.base) == 3 * (len(parts.initial) - 1) + 1
    assert_allclose(ccs.base[::3], parts.initial, rtol=0, atol=1e-6)
    assert_allclose(ccs.top[::3], parts.target, rtol=0, atol=1e-6)
    u = np.linspace(parts.surface.params[0], parts.surface.params[1], 4)[1:3]
    assert_allclose(ccs.base[1:3], parts.surface.base(u), rtol=0, atol=1e-6)
