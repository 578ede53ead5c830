"""Shape similarity of a simplified contour to its initial contour (paper section 2.3.2, eq. 7-9).

The "improved Fréchet distance" is the discrete Fréchet distance after both curves are resampled equally
spaced with the same number of points. The count comes from the initial contour's length at a fixed spacing
(dF depends on sampling density, so a fixed count would make long and short contours incomparable), capped
at ``max_points`` so a 200 km contour stays affordable; the cap bounds the sampling error of Sim by
1 / (2 * max_points). Short contours get at least ``min_points``: at 10 m a 100 m contour would have 11
samples, and the resulting wobble of Sim (up to about 1e-3) made Sim(t) rise between neighbouring t on a
few percent of the sample's contours; 256 samples remove most of that at negligible cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.errors import InvalidParameter
from engine.geom.kernels import discrete_frechet, resampled
from engine.geom.polyline import closed_path, path_length, resample_by_arclength
from engine.types import Coords

DEFAULT_SPACING_M = 10.0
DEFAULT_MAX_POINTS = 2000
DEFAULT_MIN_POINTS = 256


def _diagonal_bound(p: Coords, q: Coords) -> float:
    """Length of the coupling that walks both sequences in step: an upper bound of their discrete Fréchet."""
    n, m = len(p), len(q)
    if n >= m:
        j = np.rint(np.arange(n) * ((m - 1) / max(n - 1, 1))).astype(np.intp)
        return float(np.sqrt(np.max(np.sum((p - q[j]) ** 2, axis=1))))
    i = np.rint(np.arange(m) * ((n - 1) / max(m - 1, 1))).astype(np.intp)
    return float(np.sqrt(np.max(np.sum((p[i] - q) ** 2, axis=1))))


def discrete_frechet_distance(p: Coords, q: Coords) -> float:
    """Exact discrete Fréchet distance between two point sequences (n, 2) and (m, 2).

    Examples
    --------
    >>> discrete_frechet_distance(np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 1.0]]))
    1.0
    """
    p = np.ascontiguousarray(p, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    if len(p) == 0 or len(q) == 0:
        raise InvalidParameter("discrete Fréchet needs non-empty point sequences")
    return float(discrete_frechet(p, q, _diagonal_bound(p, q)))


def resample_count(
    length_m: float,
    spacing_m: float = DEFAULT_SPACING_M,
    max_points: int = DEFAULT_MAX_POINTS,
    min_points: int = DEFAULT_MIN_POINTS,
) -> int:
    """Samples for a curve of this length: one per ``spacing_m``, at least ``min_points``, at most ``max_points``."""
    return int(min(max(min_points, 2, round(length_m / spacing_m) + 1), max_points))


@dataclass(frozen=True)
class SimilarityReference:
    """An initial contour prepared once for many similarity measurements against versions of it.

    Attributes
    ----------
    samples
        (n, 2) the initial contour resampled equally spaced (a ring as a closed path).
    length_m
        Length of the initial contour.
    closed
        Whether it is a ring.
    """

    samples: Coords
    length_m: float
    closed: bool

    @classmethod
    def of(
        cls,
        initial: Coords,
        closed: bool,
        spacing_m: float = DEFAULT_SPACING_M,
        max_points: int = DEFAULT_MAX_POINTS,
    ) -> SimilarityReference:
        """Prepare ``initial`` ((n, 2) metres, a ring without its repeated first vertex)."""
        path = closed_path(initial) if closed else initial
        length = path_length(path)
        if not length > 0:
            raise InvalidParameter("similarity needs an initial contour of positive length")
        n = resample_count(length, spacing_m, max_points)
        return cls(samples=resample_by_arclength(path, n), length_m=length, closed=closed)

    def frechet(self, other: Coords) -> float:
        """The paper's improved Fréchet distance (eq. 8) to ``other`` (same ring convention as the initial
        contour), metres: ``other`` resampled with as many equally spaced points as the initial contour (a ring
        from its first vertex round to itself), then the exact discrete Fréchet distance."""
        path = closed_path(other) if self.closed else other
        return discrete_frechet_distance(self.samples, resample_by_arclength(path, len(self.samples)))

    def similarity(self, other: Coords) -> float:
        """Sim(L0, other) = 1 - dF / Length(L0)  (eq. 9)."""
        return 1.0 - self.frechet(other) / self.length_m

    def slice_similarities(self, base: Coords, top: Coords, ts: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sim(L0, slice(t)) for every ``t`` of ``ts``, the slices ``(1 - t) base + t top`` of two rows.

        The same numbers as :meth:`similarity` of each slice, in one compiled pass: a contour of a few dozen
        vertices spent most of its table in per-call overhead (eleven slices, each resampled and measured
        by a dozen NumPy calls). ``base`` and ``top`` are (M, 2) rows of equal length; a ring's rows are
        closed paths (first point repeated last, as ``CCS.base``), which is what :meth:`similarity` makes
        of a ring's slice.
        """
        rows = [np.ascontiguousarray(r, dtype=np.float64) for r in (base, top)]
        if rows[0].shape != rows[1].shape or rows[0].ndim != 2 or len(rows[0]) < 2:
            raise InvalidParameter("slice similarities need two rows of the same (M >= 2, 2) shape")
        if self.closed and not (np.array_equal(rows[0][0], rows[0][-1]) and np.array_equal(rows[1][0], rows[1][-1])):
            raise InvalidParameter("a ring's rows must be closed paths (first point repeated last)")
        out = np.empty(len(ts))
        _slice_similarities(self.samples, self.length_m, rows[0], rows[1], np.asarray(ts, dtype=np.float64), out)
        return out


# numba's cache keys a kernel on its own file only: it keeps the compiled discrete_frechet and resampled it was
# built with until this file changes, so a change of either comes with a touch here.
@njit(cache=True)
def _slice_similarities(samples, length, base, top, ts, out):  # pragma: no cover - compiled
    """``out[k]`` = 1 - dF(samples, slice(ts[k]) resampled to len(samples) points) / length.

    Step by step what ``SimilarityReference.similarity`` does with NumPy (each slice resampled by
    ``resample_by_arclength``'s own kernel; the diagonal coupling as the Fréchet bound), so the results agree to
    the last bit.
    """
    n = samples.shape[0]
    m = base.shape[0]
    path = np.empty((m, 2))
    for k in range(ts.shape[0]):
        t = ts[k]
        for i in range(m):
            path[i, 0] = (1.0 - t) * base[i, 0] + t * top[i, 0]
            path[i, 1] = (1.0 - t) * base[i, 1] + t * top[i, 1]
        slice_points = resampled(path, n)
        bound2 = 0.0
        for i in range(n):
            dx = samples[i, 0] - slice_points[i, 0]
            dy = samples[i, 1] - slice_points[i, 1]
            bound2 = max(bound2, dx**2 + dy**2)
        out[k] = 1.0 - discrete_frechet(samples, slice_points, np.sqrt(bound2)) / length


def similarity(
    initial: Coords,
    other: Coords,
    closed: bool,
    spacing_m: float = DEFAULT_SPACING_M,
    max_points: int = DEFAULT_MAX_POINTS,
) -> float:
    """Sim(L0, L) = 1 - dF(L0, L) / Length(L0)  (paper eq. 9); 1 for identical curves."""
    return SimilarityReference.of(initial, closed, spacing_m, max_points).similarity(other)
