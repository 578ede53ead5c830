"""Shared types of the engine.

The simplification parameter ``t``
----------------------------------
``t`` is a float in [0, 1] that says how far a contour is generalized along its continuous changing surface
(CCS): ``t = 0`` is the initial contour ``L0`` at full detail (the source scale), ``t = 1`` is the target
contour ``Ln`` (the target scale). The CCS is the ruled surface ``S(u, t) = (1 - t) C0(u) + t Cn(u)``, and
the slice at ``t`` is the cut of the CCS by the horizontal plane at that height (heights are stored as ``t``
itself, so ``Zmin = 0`` and ``Zmax = 1``). A map zoom ``z`` maps to a scale denominator, the scale to a
similarity through the regression model, and the similarity to ``t`` through the contour's own Sim(t) table
(:mod:`engine.ccsm.regression`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, TypeAlias, overload

import numpy as np
from numpy.typing import NDArray

#: (n, 2) float64 coordinates in metres of a projected CRS, (x, y) order.
Coords: TypeAlias = NDArray[np.float64]

#: Feature ids come from the input file (its id or its index).
FeatureId: TypeAlias = str | int


class Bounds(NamedTuple):
    """(minx, miny, maxx, maxy) rectangle; units as stated where it is used (EPSG:3857 metres or degrees)."""

    minx: float
    miny: float
    maxx: float
    maxy: float


@dataclass(frozen=True)
class Contour:
    """One contour line in the working (projected, metric) CRS.

    Attributes
    ----------
    id
        The input feature's id, or its index in the input.
    elevation
        Height of the contour, in the data's vertical unit.
    coords
        (n, 2) float64 vertices in metres. A closed ring is stored *without* repeating its first vertex.
    closed
        True for a ring, False for an open line (cut by the data's edge); open lines keep both ends fixed.
    """

    id: FeatureId
    elevation: float
    coords: Coords
    closed: bool

    @property
    def n_vertices(self) -> int:
        """Number of stored vertices."""
        return int(self.coords.shape[0])


class ContourSubset(Sequence[Contour]):
    """The contours at ``positions`` (increasing) of a sequence, each read from it when asked: the usable
    contours of a set whose contours wait on disk (``engine.scratch``). A slice costs one slice of the
    underlying sequence, so reading in chunks stays one read per chunk.
    """

    #: Contours read at a time when iterated.
    BATCH = 512

    def __init__(self, contours: Sequence[Contour], positions: Sequence[int]) -> None:
        self.contours = contours
        self.positions = np.asarray(positions, dtype=np.int64)  # 8 bytes a contour, not a Python int's 36

    def __len__(self) -> int:
        return len(self.positions)

    @overload
    def __getitem__(self, index: int) -> Contour: ...

    @overload
    def __getitem__(self, index: slice) -> list[Contour]: ...

    def __getitem__(self, index: int | slice) -> Contour | list[Contour]:
        if isinstance(index, slice):
            wanted = self.positions[index]
            if not len(wanted):
                return []
            lo, hi = int(wanted.min()), int(wanted.max())
            span = self.contours[lo : hi + 1]
            return [span[p - lo] for p in wanted.tolist()]
        return self.contours[int(self.positions[index])]

    def __iter__(self) -> Iterator[Contour]:
        for start in range(0, len(self), self.BATCH):
            yield from self[start : start + self.BATCH]

    def payloads(self, indices: Sequence[int]) -> list[Contour | bytes]:
        """Contours ``indices`` as the underlying sequence keeps them (see :func:`contour_payloads`)."""
        return contour_payloads(self.contours, self.positions[np.asarray(indices, dtype=np.int64)].tolist())


def contour_payloads(contours: Sequence[Contour], indices: Sequence[int]) -> list[Contour | bytes]:
    """Contours ``indices`` of a sequence as it keeps them: the pickles of contours waiting on disk
    (``engine.scratch.ScratchContours``), unopened, or the contours themselves; a task takes them to a
    worker, which opens them (``engine.payloads.opened``)."""
    take = getattr(contours, "payloads", None)
    return take(indices) if take is not None else [contours[int(i)] for i in indices]


@dataclass(frozen=True)
class BadFeature:
    """A feature that could not be used, and why (``where`` names the file or layer it came from)."""

    id: FeatureId
    reason: str
    where: str = ""


@dataclass(frozen=True)
class ContourIssue:
    """A per-contour step of the build that could not finish: the contour is served without that part.

    ``step`` names the part ("surface": served as its input geometry, "repair": kept at its last target,
    "labels": no label); ``fid`` is the stored row's id once known.
    """

    contour_id: FeatureId
    step: str
    reason: str
    fid: int | None = None


@dataclass
class ContourSet:
    """Contours read from one source, in a metric working CRS, with the CRS facts needed to write them back.

    Attributes
    ----------
    contours
        Usable contours, coordinates in metres of ``working_crs``.
    working_crs
        The projected CRS simplification happens in (``"EPSG:32616"``, ...), as an authority string or WKT.
    source_crs
        The CRS of the input, as an authority string or WKT.
    bad_features
        Every input feature that was left out, with its reason.
    name
        A human name for the set (file stem by default).
    """

    contours: Sequence[Contour]
    working_crs: str
    source_crs: str
    bad_features: list[BadFeature] = field(default_factory=list)
    name: str = "contours"
    interval: float | None = None
