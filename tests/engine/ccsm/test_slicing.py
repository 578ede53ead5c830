"""Tests of engine.ccsm.slicing: the ruled closed form against trimesh's plane section of the CCS-mesh."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import shapely
from numpy.testing import assert_allclose
from trimesh.intersections import mesh_plane

from engine.ccsm.ccs import CCS, build_ccs
from engine.ccsm.slicing import (
    MAX_MESH_ROWS,
    MESH_DEVIATION_M,
    ccs_mesh,
    check_t,
    mesh_rows,
    section_with_trimesh,
    slice_rows,
)
from engine.errors import InvalidParameter
from engine.params import BuildParams
from engine.types import Contour

INSIDE = [0.05, 0.25, 0.5, 0.77, 0.95]


@pytest.fixture
def ring_ccs(noisy_ellipse_ring: Contour) -> CCS:
    return build_ccs(noisy_ellipse_ring, BuildParams())


@pytest.fixture
def line_ccs(noisy_open_line: Contour) -> CCS:
    return build_ccs(noisy_open_line, BuildParams())


def twist_bound(base: np.ndarray, top: np.ndarray, t: float, heights: int) -> float:
    """Largest distance of a trimesh section vertex from the iso-t line of the ruled quads.

    Each quad between mesh rows r and r + 1 is split by the diagonal (i, r)-(i + 1, r + 1); the plane at
    fraction f between the rows crosses that diagonal at (1 - f) a + f d, which lies
    f (1 - f) |a + d - b - c| = f (1 - f) / (heights - 1) * |Δ_i(top - base)| off the straight iso-t segment.
    """
    r = t * (heights - 1)
    f = r - np.floor(r)
    jump = np.linalg.norm(np.diff(top - base, axis=0), axis=1).max()
    return float(f * (1.0 - f) / (heights - 1) * jump)


def trimesh_segments(
    base: np.ndarray, top: np.ndarray, t: float, heights: int = 4
) -> shapely.MultiLineString:
    """trimesh's raw plane/mesh intersection segments (no chaining), as an oracle for open lines too."""
    segments = mesh_plane(ccs_mesh(base, top, heights), [0.0, 0.0, 1.0], [0.0, 0.0, t])
    return shapely.MultiLineString([seg[:, :2] for seg in segments])


# --- the closed form --------------------------------------------------------------------------------------


def test_slice_rows_is_the_weighted_sum_of_the_rows() -> None:
    base = np.array([[0.0, 0.0], [10.0, 0.0]])
    top = np.array([[0.0, 4.0], [10.0, 8.0]])
    assert_allclose(slice_rows(base, top, 0.25), [[0.0, 1.0], [10.0, 2.0]], atol=1e-12)


@pytest.mark.parametrize("which", ["ring", "line"])
def test_slice_at_zero_is_base_and_at_one_is_top(which: str, ring_ccs: CCS, line_ccs: CCS) -> None:
    ccs = ring_ccs if which == "ring" else line_ccs
    assert_allclose(slice_rows(ccs.base, ccs.top, 0.0), ccs.base, rtol=0, atol=0)
    assert_allclose(slice_rows(ccs.base, ccs.top, 1.0), ccs.top, rtol=0, atol=0)


@pytest.mark.parametrize("t", [0.0, *INSIDE, 1.0])
def test_a_ring_slices_to_a_closed_ring(t: float, ring_ccs: CCS) -> None:
    sliced = slice_rows(ring_ccs.base, ring_ccs.top, t)
    assert_allclose(sliced[-1], sliced[0], rtol=0, atol=1e-9)
    assert shapely.LinearRing(sliced).is_closed


@pytest.mark.parametrize("t", [-0.01, 1.0001, float("nan"), 2.0])
def test_t_outside_the_unit_interval_raises(t: float) -> None:
    with pytest.raises(InvalidParameter, match="t must lie"):
        slice_rows(np.zeros((2, 2)), np.ones((2, 2)), t)


def test_check_t_returns_a_float() -> None:
    value = check_t(np.float32(0.5))
    assert type(value) is float and value == 0.5


@pytest.mark.parametrize("which", ["ring", "line"])
def test_slice_distance_to_the_target_shrinks_monotonically_with_t(
    which: str, ring_ccs: CCS, line_ccs: CCS
) -> None:
    ccs = ring_ccs if which == "ring" else line_ccs
    target = shapely.LineString(ccs.top)
    ts = np.linspace(0.0, 1.0, 21)
    distances = [
        shapely.hausdorff_distance(shapely.LineString(slice_rows(ccs.base, ccs.top, t)), target) for t in ts
    ]
    assert np.all(np.diff(distances) <= 1e-9)
    assert distances[-1] == pytest.approx(0.0, abs=1e-9)


# --- trimesh as the oracle --------------------------------------------------------------------------------


@pytest.mark.parametrize("t", [1.0 / 3.0, 2.0 / 3.0])
def test_ring_slice_equals_trimesh_section_at_mesh_row_heights(t: float, ring_ccs: CCS) -> None:
    sections = section_with_trimesh(ccs_mesh(ring_ccs.base, ring_ccs.top, heights=4), t)
    assert len(sections) == 1
    ours = shapely.LineString(slice_rows(ring_ccs.base, ring_ccs.top, t))
    assert shapely.hausdorff_distance(shapely.LineString(sections[0]), ours) < 1e-6


@pytest.mark.parametrize("heights", [4, 10])
@pytest.mark.parametrize("t", INSIDE)
def test_ring_slice_is_within_the_diagonal_twist_of_trimesh_section(
    t: float, heights: int, ring_ccs: CCS
) -> None:
    sections = section_with_trimesh(ccs_mesh(ring_ccs.base, ring_ccs.top, heights), t)
    assert len(sections) == 1
    assert np.allclose(sections[0][0], sections[0][-1])  # trimesh chains the ring's section into a loop
    ours = shapely.LineString(slice_rows(ring_ccs.base, ring_ccs.top, t))
    distance = shapely.hausdorff_distance(shapely.LineString(sections[0]), ours)
    assert distance <= twist_bound(ring_ccs.base, ring_ccs.top, t, heights) + 1e-6


@pytest.mark.parametrize("t", INSIDE)
def test_line_slice_is_within_the_diagonal_twist_of_trimeshs_section_segments(
    t: float, line_ccs: CCS
) -> None:
    ours = shapely.LineString(slice_rows(line_ccs.base, line_ccs.top, t))
    distance = shapely.hausdorff_distance(trimesh_segments(line_ccs.base, line_ccs.top, t), ours)
    assert distance <= twist_bound(line_ccs.base, line_ccs.top, t, 4) + 1e-6


def test_section_with_trimesh_returns_the_section_of_an_open_line(line_ccs: CCS) -> None:
    assert len(section_with_trimesh(line_ccs.mesh(), 0.5)) == 1


@pytest.mark.parametrize("t", [0.0137, 0.5003, 0.9871])
@pytest.mark.parametrize("shape", ["ring", "line"])
def test_slice_matches_trimesh_section_of_the_default_mesh_within_1_cm_or_the_capped_twist(
    t: float, shape: str, ring_ccs: CCS, line_ccs: CCS
) -> None:
    ccs = ring_ccs if shape == "ring" else line_ccs
    sections = section_with_trimesh(ccs.mesh(), t)
    assert len(sections) == 1
    ours = shapely.LineString(slice_rows(ccs.base, ccs.top, t))
    distance = shapely.hausdorff_distance(shapely.LineString(sections[0]), ours)
    rows = mesh_rows(ccs.base, ccs.top)
    if rows < MAX_MESH_ROWS:
        assert distance <= MESH_DEVIATION_M
    else:  # the ring's mesh hits the row cap: its twist may exceed 1 cm (1.1 cm at t = 0.5003)
        assert distance <= twist_bound(ccs.base, ccs.top, t, rows) + 1e-9
        assert distance <= 0.012


def test_ccs_mesh_has_the_rows_as_vertices_and_heights_as_z(ring_ccs: CCS) -> None:
    mesh = ccs_mesh(ring_ccs.base, ring_ccs.top, heights=5)
    m = len(ring_ccs.base)
    assert mesh.vertices.shape == (5 * m, 3)
    assert mesh.faces.shape == (2 * 4 * (m - 1), 3)
    assert_allclose(np.unique(mesh.vertices[:, 2]), [0.0, 0.25, 0.5, 0.75, 1.0], atol=1e-15)


def test_ccs_mesh_rejects_fewer_than_two_heights() -> None:
    with pytest.raises(InvalidParameter):
        ccs_mesh(np.zeros((3, 2)), np.ones((3, 2)), heights=1)


def test_builds_and_the_service_start_without_loading_the_oracle() -> None:
    """trimesh serves only as the test oracle; loading it costs every build worker and server half a second."""
    code = (
        "import sys, engine.build.datasets, engine.serve.renderer, app.main; "
        "print(sorted(m for m in ('trimesh', 'networkx') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
