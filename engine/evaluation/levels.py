"""The four methods' level ladders in one compact form (paper section 3.2.1, Table 1).

Every method gives ``levels`` results per contour, level 0 the initial contour ``L0`` and the last level the
most simplified one (the paper's Fig. 10 numbers them 1..100; here they are 0-based). Two forms cover all
four methods without storing every level's coordinates:

- :class:`VertexLadder` (DP, WM, VW): every baseline level is a nested subset of the input's vertices, so a
  level is ``coords[rank >= i]``: one small integer per input vertex holds the whole ladder.
- :class:`SurfaceLadder` (CCSM): level ``i`` is the CCS slice at ``t_i``, one weighted sum of the surface's
  two stored rows.

``at(i)`` returns (k, 2) float64 metres; a ring *without* its repeated first vertex, started at a vertex that
every level keeps, so the ring similarity (which walks a ring from its first vertex round to itself) compares
like with like.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from engine.baselines import ladder as baseline_ladder
from engine.baselines import simplify_at_scale
from engine.ccsm.ccs import CCS, build_ccs
from engine.ccsm.slicing import slice_rows
from engine.errors import InvalidParameter
from engine.method_names import BASELINE_METHODS, CCSM, COMPARED_METHODS
from engine.params import BuildParams
from engine.types import Contour, Coords

#: Methods compared, in the order of every table and figure.
EVAL_METHODS: tuple[str, ...] = COMPARED_METHODS


@dataclass(frozen=True)
class VertexLadder:
    """A baseline's levels as a rank per input vertex."""

    #: (n, 2) the input contour (a ring without its repeated vertex), rotated so that ``coords[0]`` is kept by every
    #: level.
    coords: Coords
    #: (n,) int: the last level that keeps each vertex (``levels - 1`` for vertices kept throughout).
    rank: NDArray[np.int32]
    #: Whether the contour is a ring.
    closed: bool
    #: Number of levels.
    levels: int

    def at(self, i: int) -> Coords:
        """Level ``i`` (0-based): (k, 2) metres."""
        return self.coords[self.rank >= _check_level(i, self.levels)]

    def vertex_counts(self) -> NDArray[np.intp]:
        """(levels,) vertex count of every level."""
        hist = np.bincount(self.rank, minlength=self.levels)
        return np.cumsum(hist[::-1])[::-1].astype(np.intp)


@dataclass(frozen=True)
class SurfaceLadder:
    """CCSM's levels: slices of a CCS at evenly spaced t (the paper's 100 horizontal planes)."""

    #: base, top: (M, 2) the CCS's rows at t = 0 and t = 1 (a ring as a closed path).
    base: Coords
    top: Coords
    #: (levels,) t of each level, 0 ... 1.
    t: NDArray[np.float64]
    #: Whether the contour is a ring.
    closed: bool

    @property
    def levels(self) -> int:
        """Number of levels."""
        return int(len(self.t))

    def at(self, i: int) -> Coords:
        """Level ``i`` (0-based): the slice at ``t[i]``, (M, 2) metres; a ring without its repeated point."""
        path = slice_rows(self.base, self.top, float(self.t[_check_level(i, self.levels)]))
        return path[:-1] if self.closed else path

    @property
    def start(self) -> Coords:
        """(2,) the first point of every level (a characteristic point of L0)."""
        return self.base[0]


Ladder = VertexLadder | SurfaceLadder


def _check_level(i: int, levels: int) -> int:
    if not 0 <= i < levels:
        raise InvalidParameter(f"level {i} outside 0..{levels - 1}")
    return int(i)


@njit(cache=True)
def _walk_ranks(
    coords: Coords, flat: Coords, offsets: NDArray[np.intp]
) -> NDArray[np.int32]:  # pragma: no cover - numba
    """Rank per vertex from nested ordered subsets, by one merge walk per level; -2 marks a failure."""
    n = coords.shape[0]
    rank = np.full(n, -1, dtype=np.int32)
    for level in range(offsets.shape[0] - 1):
        j = 0
        for k in range(offsets[level], offsets[level + 1]):
            # Only the previous level's vertices are candidates (a contour may pass a point twice).
            while j < n and (
                rank[j] != level - 1 or coords[j, 0] != flat[k, 0] or coords[j, 1] != flat[k, 1]
            ):
                j += 1
            if j == n:
                rank[0] = -2
                return rank
            rank[j] = level
            j += 1
    return rank


def ranks_from_levels(coords: Coords, results: list[Coords]) -> NDArray[np.int32]:
    """Turn a list of nested, order-keeping vertex subsets of ``coords`` into one rank per vertex.

    Parameters
    ----------
    coords
        (n, 2) input vertices.
    results
        ``levels`` arrays; level 0 is ``coords`` itself, each level a subsequence of the one before.

    Returns
    -------
    (n,) int32
        The last level that keeps each vertex.

    Raises
    ------
    InvalidParameter
        A level is not a subsequence of the level before it.

    Examples
    --------
    >>> xy = np.array([[0, 0], [1, 1], [2, 0], [3, 1.0]])
    >>> ranks_from_levels(xy, [xy, xy[[0, 2, 3]], xy[[0, 3]]]).tolist()
    [2, 0, 1, 2]
    """
    xy = np.ascontiguousarray(coords, dtype=np.float64)
    flat = np.ascontiguousarray(np.concatenate(results), dtype=np.float64)
    offsets = np.concatenate([[0], np.cumsum([len(r) for r in results])]).astype(np.intp)
    rank = _walk_ranks(xy, flat, offsets)
    if rank[0] == -2 or np.any(rank < 0):
        raise InvalidParameter("levels are not nested subsequences of the input")
    return rank


def vertex_ladder(
    method: str,
    contour: Contour,
    levels: int,
    level_map: NDArray[np.intp] | None = None,
    results: list[Coords] | None = None,
) -> VertexLadder:
    """A baseline's ``levels`` results for one contour as a :class:`VertexLadder`.

    ``level_map`` (optional, (levels,) non-decreasing indices into the method's own ladder) picks the levels
    used, for a ladder that stops before the method's minimal form (``--target scale``). ``results`` is the
    method's ladder when the caller has it already.
    """
    if results is None:
        results = baseline_ladder(method, contour.coords, contour.closed, levels)
    rank = ranks_from_levels(contour.coords, results)
    if level_map is not None:
        rank = (np.searchsorted(np.asarray(level_map), rank, side="right") - 1).astype(np.int32)
    coords = contour.coords
    if contour.closed:
        start = int(np.flatnonzero(rank == rank.max())[0])
        coords = np.roll(coords, -start, axis=0)
        rank = np.roll(rank, -start)
    return VertexLadder(coords=coords, rank=rank, closed=contour.closed, levels=levels)


def scale_level_map(
    method: str, contour: Contour, full: list[Coords], target_scale: float
) -> NDArray[np.intp]:
    """Levels of a method's full ladder from L0 down to its own result at ``target_scale``.

    The full ladder ends at the minimal form; its prefix that ends at the first level with no more vertices
    than ``simplify_at_scale(method, ..., target_scale)`` is stretched over ``levels`` levels.
    """
    levels = len(full)
    k = len(simplify_at_scale(method, contour.coords, contour.closed, target_scale))
    counts = np.array([len(level) for level in full])
    last = int(np.flatnonzero(counts <= k)[0]) if np.any(counts <= k) else levels - 1
    return np.rint(np.linspace(0, last, levels)).astype(np.intp)


def surface_ladder(ccs: CCS, levels: int) -> SurfaceLadder:
    """CCSM's ``levels`` results: slices at t = i / (levels - 1)."""
    return SurfaceLadder(base=ccs.base, top=ccs.top, t=np.linspace(0.0, 1.0, levels), closed=ccs.closed)


def eval_params(target: str, source_scale: float, target_scale: float) -> BuildParams:
    """Build parameters of the evaluation: the paper's extreme target (Fig. 10) or the target scale."""
    if target not in ("extreme", "scale"):
        raise InvalidParameter(f"target must be extreme or scale, got {target!r}")
    return BuildParams(
        source_scale=source_scale,
        target_scale=target_scale,
        target_mode="extreme" if target == "extreme" else "scale",
        similarity_levels=2,
        scale_mapping="log",
    )


def contour_ladders(contour: Contour, levels: int, params: BuildParams) -> dict[str, Ladder]:
    """Every method's ladder for one contour.

    Raises
    ------
    CCSMError
        The contour cannot be simplified by one of the methods (the caller lists it as a bad feature).
    """
    out: dict[str, Ladder] = {CCSM: surface_ladder(build_ccs(contour, params), levels)}
    for method in BASELINE_METHODS:
        full = baseline_ladder(method, contour.coords, contour.closed, levels)
        level_map = None
        if params.target_mode == "scale":
            level_map = scale_level_map(method, contour, full, params.target_scale)
        out[method] = vertex_ladder(method, contour, levels, level_map, full)
    return out


def rotate_ring_to(coords: Coords, start: Coords) -> Coords:
    """A ring (without repeated vertex) rotated to begin at its vertex nearest ``start``."""
    k = int(np.argmin(np.sum((coords - start) ** 2, axis=1)))
    return np.roll(coords, -k, axis=0)
