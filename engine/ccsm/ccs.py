"""The CCS of one contour: from the initial contour to a sliceable surface with its Sim(t) table.

Steps (paper section 2, docs/design.md section 2): Douglas–Peucker target -> correspondence resampling ->
degree-3 surface fit -> tessellation into two boundary rows -> similarity table.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.resample import Correspondence, correspond
from engine.ccsm.similarity import SimilarityReference
from engine.ccsm.slicing import ccs_mesh, check_t, slice_rows
from engine.ccsm.surface import CCSurface, fit_surface, surface_rows
from engine.errors import InvalidContour
from engine.geom.douglas_peucker import douglas_peucker, douglas_peucker_count
from engine.geom.kernels import path_fault
from engine.geom.polyline import closed_path, path_length, ring_area
from engine.params import BuildParams
from engine.types import Contour, Coords, FeatureId

if TYPE_CHECKING:
    import trimesh

#: A piece shorter than this many samples cannot carry a cubic; short contours get a finer spacing.
MIN_SAMPLES = 8


@dataclass
class CCS:
    """A contour's continuous changing surface, ready to slice.

    Attributes
    ----------
    contour_id, elevation, closed
        From the input contour.
    base, top
        (M, 2) tessellated rows of the surface at t = 0 (about L0) and t = 1 (Ln), metres, same CRS as the
        input. For a ring both are closed paths (the first point repeated last) that start at a
        characteristic point, in the input's direction.
    sim_t, sim
        (K,) t values from 0 to 1 and the similarity Sim(L0, slice(t)) at each (paper eq. 9), as measured.
    length_m
        Length of L0.
    target_vertices
        Vertex count of the target contour Ln.
    group
        Index of the contour's similarity-scale regression group.
    t_at_scale
        (S,) t at each scale of the dataset's scale ladder (filled by the build).
    vanish_scale
        Scale denominator from which the contour is too small to show (inf: never).
    tolerance_factor
        Share of the target scale's DP tolerance the target was made with (below 1 where the build had to
        keep more detail so this contour's slices cannot cross a neighbour's).
    """

    contour_id: FeatureId
    elevation: float
    closed: bool
    base: Coords
    top: Coords
    sim_t: NDArray[np.float64]
    sim: NDArray[np.float64]
    length_m: float
    n_input_vertices: int
    target_vertices: int
    group: int = 0
    t_at_scale: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    vanish_scale: float = float("inf")
    tolerance_factor: float = 1.0
    #: (step, reason) of each step of its build that could not finish (docs/design.md, "A failure stays with its
    #: contour"): the surface is then what that step falls back to.
    issues: tuple[tuple[str, str], ...] = ()

    def at(self, t: float) -> Coords:
        """The simplified contour at ``t`` in [0, 1]: (M, 2) metres (a ring as a closed path)."""
        return slice_rows(self.base, self.top, t)

    def similarity_at(self, t: float) -> float:
        """Sim(L0, slice(t)), interpolated from the table."""
        return float(np.interp(check_t(t), self.sim_t, self.sim))

    def mesh(self, heights: int | None = None) -> trimesh.Trimesh:
        """The CCS-mesh as a ``trimesh.Trimesh`` in (x, y, t) (rows in t: see ``engine.ccsm.slicing.mesh_rows``)."""
        return ccs_mesh(self.base, self.top, heights)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(minx, miny, maxx, maxy) of the surface (every slice lies inside)."""
        both = np.concatenate([self.base, self.top])
        lo = both.min(axis=0)
        hi = both.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


@dataclass(frozen=True)
class SurfaceParts:
    """Everything built for one contour before the similarity table, for inspection and tests."""

    path: Coords  # L0 as a path (a ring rotated to start at a characteristic point, closed)
    characteristic: NDArray[np.intp]  # indices into path of the characteristic points
    initial: Coords  # correspondence samples on L0
    target: Coords  # partner samples on Ln
    surface: CCSurface


def target_indices(
    coords: Coords, closed: bool, params: BuildParams, tolerance_factor: float = 1.0
) -> NDArray[np.intp]:
    """Characteristic points of a contour: the vertices its target contour Ln keeps.

    ``tolerance_factor`` scales the target's DP tolerance; the build lowers it for contours whose slices
    would cross a neighbour (0 keeps every vertex: Ln = L0).
    """
    if params.target_mode == "scale":
        return douglas_peucker(coords, params.target_tolerance_m * tolerance_factor, closed)
    if params.target_mode == "points":
        return douglas_peucker_count(coords, int(params.target_points or 2), closed)
    return douglas_peucker_count(coords, 3 if closed else 2, closed)


def check_contour(contour: Contour) -> None:
    """Raise InvalidContour (naming the contour) if it cannot carry a CCS."""
    xy = contour.coords
    where = f"contour {contour.id!r}"
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise InvalidContour(f"{where}: coordinates must have shape (n, 2), got {xy.shape}")
    fault = path_fault(np.ascontiguousarray(xy, dtype=np.float64), contour.closed)
    if fault == 1:
        raise InvalidContour(f"{where}: NaN or infinite coordinates")
    need = 3 if contour.closed else 2
    if len(xy) < need:
        raise InvalidContour(
            f"{where}: {len(xy)} vertices, a {'ring' if contour.closed else 'line'} needs {need}"
        )
    # One compiled pass: every build checks its contour (twice, with the set's check), and a dozen NumPy calls
    # were a thirtieth of a build. No repeated step means a positive length: a step not at the same point has
    # a length above 0, however small.
    if fault == 2:
        raise InvalidContour(f"{where}: repeated consecutive vertices")


def build_surface(contour: Contour, params: BuildParams, tolerance_factor: float = 1.0) -> SurfaceParts:
    """Steps 1-5 of CCSM for one contour: target, correspondence, surface."""
    path, keep, corr = _correspondence(contour, params, tolerance_factor)
    surface = fit_surface(corr.initial, corr.target, contour.closed)
    return SurfaceParts(path=path, characteristic=keep, initial=corr.initial, target=corr.target, surface=surface)


def _correspondence(
    contour: Contour, params: BuildParams, tolerance_factor: float
) -> tuple[Coords, NDArray[np.intp], Correspondence]:
    """Steps 1-2 of CCSM: L0 as a path, the characteristic points (indices into it) and the samples."""
    check_contour(contour)
    xy = contour.coords
    keep = target_indices(xy, contour.closed, params, tolerance_factor)
    if contour.closed:
        # Start the ring at a characteristic point so the seam is one of the fixed correspondences.
        xy = np.roll(xy, -int(keep[0]), axis=0)
        keep = np.append(keep - keep[0], len(xy))
        path = closed_path(xy)
    else:
        path = xy
    spacing = min(params.spacing_m, path_length(path) / MIN_SAMPLES)
    return path, keep, correspond(path, keep, spacing)


def build_ccs(contour: Contour, params: BuildParams, tolerance_factor: float = 1.0) -> CCS:
    """Build the CCS of one contour and its Sim(t) table (the scale table is added by the build).

    Raises
    ------
    InvalidContour
        The contour cannot be used (the message names it and says why).
    SurfaceFitError
        The surface could not be fitted.
    """
    path, keep, corr = _correspondence(contour, params, tolerance_factor)
    base, top = surface_rows(corr.initial, corr.target, contour.closed, params.tessellation_per_span)
    if contour.closed:
        base[-1] = base[0]
        top[-1] = top[0]
    l0 = path[:-1] if contour.closed else path
    sim_t = np.linspace(0.0, 1.0, params.similarity_levels)
    reference = SimilarityReference.of(l0, contour.closed, params.similarity_spacing_m)
    sims = reference.slice_similarities(base, top, sim_t)
    return CCS(
        contour_id=contour.id,
        elevation=contour.elevation,
        closed=contour.closed,
        base=base,
        top=top,
        sim_t=sim_t,
        sim=sims,
        length_m=path_length(contour.coords, contour.closed),
        n_input_vertices=contour.n_vertices,
        target_vertices=len(keep) - (1 if contour.closed else 0),
        tolerance_factor=tolerance_factor,
    )


def slice_area(ccs: CCS, t: float) -> float:
    """Area of a ring's slice at ``t`` (0 for an open line)."""
    return ring_area(ccs.at(t)[:-1]) if ccs.closed else 0.0
