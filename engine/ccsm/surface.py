"""The continuous changing surface (CCS): a degree-3 NURBS surface through the N x 4 wireframe.

The wireframe (paper section 2.2.2) has four rows: the samples of ``L0`` at height 0, the samples of ``Ln``
at height 1, and two rows at heights 1/3 and 2/3 on the straight characteristic links between them. geomdl's
global surface interpolation (NURBS Book A9.4) would fit it with chord-length parameters averaged over the
rows, knots by averaging (eq. 9.8), and a pure-Python dense LU, which takes minutes for one contour.

The same surface, computed fast: the four points on every link are collinear and evenly spaced, so the
v-direction interpolation is exactly linear and the surface is the ruled surface
``S(u, v) = (1 - v) C0(u) + v Cn(u)`` with height ``v``. Only the two boundary curves need solving: one banded
collocation system (SciPy) with geomdl's own parameters and knots. ``to_geomdl`` rebuilds the full geomdl
surface for exchange and as the test oracle. Rings use periodic knots (SciPy's periodic interpolation with
the same averaged parameters); clamped knots would leave a kink at the seam.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.errors import SurfaceFitError
from engine.types import Coords

if TYPE_CHECKING:
    from geomdl import BSpline as GeomdlBSpline
    from scipy.interpolate import BSpline

DEGREE = 3
#: Heights of the wireframe rows on every characteristic link (paper: four points per link).
WIREFRAME_HEIGHTS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
#: A column whose largest share of its row's length is at least this rises clearly: the averaged parameters'
#: rounding (a few 1e-16 on values up to 1) cannot make it equal to the one before.
CLEAR_RISE = 1e-12


def wireframe(initial: Coords, target: Coords) -> NDArray[np.float64]:
    """The (4, N, 3) wireframe: four evenly spaced points on each characteristic link, height = row fraction."""
    rows = []
    for h in WIREFRAME_HEIGHTS:
        xy = (1.0 - h) * initial + h * target
        rows.append(np.column_stack([xy, np.full(len(xy), h)]))
    return np.stack(rows)


def averaged_parameters(grid: NDArray[np.float64]) -> NDArray[np.float64]:
    """Chord-length parameters of each row, averaged over the rows (NURBS Book eq. 9.4-9.5, p. 366).

    Parameters
    ----------
    grid
        (rows, N, dim) points.

    Returns
    -------
    (N,) parameters from 0 to 1.
    """
    chords = np.linalg.norm(np.diff(grid, axis=1), axis=2)  # (rows, N - 1)
    totals = chords.sum(axis=1, keepdims=True)
    if np.any(totals <= 0):
        raise SurfaceFitError("a wireframe row has zero length")
    params = np.concatenate([np.zeros((len(grid), 1)), np.cumsum(chords / totals, axis=1)], axis=1)
    params[:, -1] = 1.0
    return params.mean(axis=0)


def averaged_knots(params: NDArray[np.float64], degree: int = DEGREE) -> NDArray[np.float64]:
    """Clamped knot vector by averaging the parameters (NURBS Book eq. 9.8), as geomdl computes it."""
    n = len(params)
    sums = np.cumsum(np.concatenate([[0.0], params]))
    j = np.arange(1, n - degree)
    inner = (sums[j + degree] - sums[j]) / degree
    return np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])


@dataclass(frozen=True)
class CCSurface:
    """The fitted CCS.

    Attributes
    ----------
    params
        (N,) averaged u parameters of the wireframe columns (the data points lie at these u).
    base
        B-spline curve C0(u) (the surface at height 0), values (x, y) in metres.
    top
        B-spline curve Cn(u) (the surface at height 1).
    closed
        Periodic in u (a ring).
    """

    params: NDArray[np.float64]
    base: BSpline
    top: BSpline
    closed: bool

    def evaluate(self, u: NDArray[np.float64], v: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """Surface points (x, y, height) at parameters ``u`` (m,) and height ``v`` (scalar or (m,))."""
        c0 = self.base(u)
        cn = self.top(u)
        vv = np.broadcast_to(np.asarray(v, dtype=float), (len(u),))
        xy = (1.0 - vv)[:, None] * c0 + vv[:, None] * cn
        return np.column_stack([xy, vv])

    def curves_to_geomdl(self) -> tuple[GeomdlBSpline.Curve, GeomdlBSpline.Curve]:
        """The boundary curves L0' (height 0) and Ln' (height 1) as geomdl ``BSpline.Curve`` objects (degree 3).

        Only for open contours: geomdl has no periodic knot vectors.
        """
        from geomdl import BSpline as GeomdlBSpline

        if self.closed:
            raise SurfaceFitError("geomdl has no periodic curves; a ring's boundary cannot be exported to it")
        curves = []
        for spline in (self.base, self.top):
            curve = GeomdlBSpline.Curve()
            curve.degree = DEGREE
            curve.ctrlpts = [[float(x), float(y)] for x, y in spline.c]
            curve.knotvector = [float(k) for k in spline.t]
            curves.append(curve)
        return curves[0], curves[1]

    def to_geomdl(self) -> GeomdlBSpline.Surface:
        """The surface as a geomdl ``BSpline.Surface`` (degree 3 x 3, control net N x 4).

        Only for open contours: geomdl has no periodic knot vectors.
        """
        from geomdl import BSpline as GeomdlBSpline

        if self.closed:
            raise SurfaceFitError("geomdl has no periodic surfaces; a ring's CCS cannot be exported to it")
        c0 = self.base.c
        cn = self.top.c
        net = []
        for i in range(len(c0)):
            for h in WIREFRAME_HEIGHTS:
                # The Bézier control points of a linear function in v are its values at 0, 1/3, 2/3, 1.
                xy = (1.0 - h) * c0[i] + h * cn[i]
                net.append([float(xy[0]), float(xy[1]), h])
        surf = GeomdlBSpline.Surface()
        surf.degree_u = DEGREE
        surf.degree_v = DEGREE
        surf.ctrlpts_size_u = len(c0)
        surf.ctrlpts_size_v = len(WIREFRAME_HEIGHTS)
        surf.ctrlpts = net
        surf.knotvector_u = [float(k) for k in self.base.t]
        surf.knotvector_v = [0.0] * 4 + [1.0] * 4
        return surf


def fit_parameters(initial: Coords, target: Coords) -> NDArray[np.float64]:
    """The (N,) averaged u parameters of the wireframe through ``initial`` and ``target``, checked for a fit.

    Raises
    ------
    SurfaceFitError
        Too few samples, rows of different shapes, or repeated samples (equal parameters).
    """
    if len(initial) < DEGREE + 1 or initial.shape != target.shape:
        raise SurfaceFitError(f"need at least {DEGREE + 1} corresponding samples, got {len(initial)}")
    params = averaged_parameters(wireframe(initial, target))
    if np.any(np.diff(params) <= 0):
        raise SurfaceFitError("repeated samples give equal surface parameters")
    return params


def check_fit(initial: Coords, target: Coords) -> None:
    """Raise what :func:`fit_parameters` raises, without making the parameters when they clearly rise.

    A build with no samples between the data parameters (``tessellation_per_span`` 0) only needs the check,
    and making the (4, N, 3) wireframe to check it was a seventh of each contour's surface: one compiled pass
    over the rows' chords settles it for every column that takes a clear share of a row's length; anything
    closer is checked exactly as the fit checks it.
    """
    if (
        len(initial) >= DEGREE + 1
        and initial.shape == target.shape
        and initial.ndim == 2
        and _rises_clearly(
            np.ascontiguousarray(initial, dtype=np.float64),
            np.ascontiguousarray(target, dtype=np.float64),
            np.array(WIREFRAME_HEIGHTS),
            CLEAR_RISE,
        )
    ):
        return
    fit_parameters(initial, target)


@njit(cache=True)
def _rises_clearly(initial, target, heights, share):  # pragma: no cover - compiled
    """Whether every wireframe row has a length and every column takes at least ``share`` of some row's length
    (so the averaged parameters rise there whatever their rounding). False sends the rows to the exact check."""
    n = initial.shape[0]
    chords = np.empty((heights.shape[0], n - 1))
    for r in range(heights.shape[0]):
        h = heights[r]
        total = 0.0
        for i in range(n - 1):
            dx = ((1.0 - h) * initial[i + 1, 0] + h * target[i + 1, 0]) - ((1.0 - h) * initial[i, 0] + h * target[i, 0])
            dy = ((1.0 - h) * initial[i + 1, 1] + h * target[i + 1, 1]) - ((1.0 - h) * initial[i, 1] + h * target[i, 1])
            chords[r, i] = np.hypot(dx, dy)
            total += chords[r, i]
        # Far from underflow (where the fit's own norm of a tiny chord could round to 0) and from overflow.
        if not (total > 1e-100 and total < np.inf):
            return False
        for i in range(n - 1):
            chords[r, i] /= total
    for i in range(n - 1):
        best = 0.0
        for r in range(heights.shape[0]):
            best = max(best, chords[r, i])
        if not best >= share:
            return False
    return True


def fit_surface(initial: Coords, target: Coords, closed: bool) -> CCSurface:
    """Fit the CCS through corresponding samples of ``L0`` and ``Ln``.

    Parameters
    ----------
    initial, target
        (N, 2) corresponding samples in metres (for a ring: the closed path, first sample repeated last).
    closed
        Fit periodic curves (a ring).

    Returns
    -------
    CCSurface

    Raises
    ------
    SurfaceFitError
        Too few samples, or a singular collocation system.
    """
    # Imported here: a build without extra rows between samples (the default) never solves a spline, and
    # SciPy's splines were a quarter of a second of every process's start.
    from scipy.interpolate import BSpline, make_interp_spline

    params = fit_parameters(initial, target)
    data = np.concatenate([initial, target], axis=1)  # (N, 4): both boundary rows in one solve
    try:
        if closed:
            spline = make_interp_spline(params, data, k=DEGREE, bc_type="periodic")
        else:
            spline = make_interp_spline(params, data, k=DEGREE, t=averaged_knots(params))
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise SurfaceFitError(f"surface fit failed: {exc}") from exc
    base = BSpline(spline.t, spline.c[:, :2], DEGREE, extrapolate=spline.extrapolate)
    top = BSpline(spline.t, spline.c[:, 2:], DEGREE, extrapolate=spline.extrapolate)
    return CCSurface(params=params, base=base, top=top, closed=closed)


def tessellation_parameters(params: NDArray[np.float64], per_span: int) -> NDArray[np.float64]:
    """u values of the tessellation: every data parameter plus ``per_span`` evenly spaced ones in between."""
    if per_span <= 0:
        return params.copy()
    steps = np.arange(per_span + 1) / (per_span + 1)
    inner = params[:-1, None] + np.diff(params)[:, None] * steps[None, :]
    return np.concatenate([inner.ravel(), params[-1:]])


def surface_rows(initial: Coords, target: Coords, closed: bool, per_span: int) -> tuple[Coords, Coords]:
    """The tessellated rows ``base`` (height 0) and ``top`` (height 1) of the CCS through these samples.

    With ``per_span`` = 0 the rows are the curves at their own data parameters, and an interpolating curve
    passes through its data there: the rows are the samples themselves, so they are taken as they are and no
    spline is solved (the fit's checks still run). Only extra samples between data parameters need the fit.

    Parameters
    ----------
    initial, target
        (N, 2) corresponding samples, as for :func:`fit_surface`.
    closed
        A ring (periodic curves).
    per_span
        ``BuildParams.tessellation_per_span``.

    Raises
    ------
    SurfaceFitError
        As :func:`fit_surface`.
    """
    if per_span <= 0:
        check_fit(initial, target)
        return initial.copy(), target.copy()
    surface = fit_surface(initial, target, closed)
    u = tessellation_parameters(surface.params, per_span)
    return surface.base(u), surface.top(u)
