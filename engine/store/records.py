"""The records a store reads and writes: plain frozen dataclasses of numbers and arrays, no SQL.

What a build hands over (:class:`NewDataset`, :class:`NewContour`, :class:`StoredLabels`) and what a reader gets
back (:class:`DatasetInfo`, :class:`ContourRecord`, :class:`ContourHead`, :class:`StoredPieces`); how they become
columns is :mod:`engine.store.codec`. :class:`LabelAnchors` is the one definition of a placed label set: the
cartography places it (:func:`engine.cartography.labels.place_labels`), the store keeps it as it is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.types import Coords


@dataclass(frozen=True)
class DatasetInfo:
    """A stored dataset's metadata."""

    id: str
    name: str
    source: str
    source_hash: str
    params: dict[str, Any]
    #: Increases with every write of the dataset; tiles are deterministic given it.
    data_version: int
    built_at: float
    build_seconds: float
    working_crs: str
    source_crs: str
    interval: float | None
    #: (minx, miny, maxx, maxy) of every contour's CCS, EPSG:3857 metres.
    bounds_3857: tuple[float, float, float, float]
    n_contours: int
    n_closed: int
    n_vertices: int
    source_scale: float
    target_scale: float
    #: (S,) scale denominators at which each contour's t is tabulated.
    ladder: NDArray[np.float64]
    bad_features: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class ContourColumns:
    """The columns of one contour that a build writes and a reader gets back (:class:`NewContour`,
    :class:`ContourRecord`).
    """

    contour_id: str
    elevation: float
    closed: bool
    group: int
    vanish_scale: float
    length_m: float
    #: base, top: (M, 2) CCS rows in EPSG:3857 metres (a ring as a closed path).
    base: Coords
    top: Coords
    #: (n, 2) input contour in EPSG:3857 (a ring as a closed path).
    original: Coords
    #: (n, 2) input contour in the working CRS, metres (a ring *without* its repeated vertex).
    original_w: Coords
    #: (S,) t at each scale of the dataset's ladder.
    t_at_scale: NDArray[np.float64]
    #: sim_t, sim: the Sim(t) table.
    sim_t: NDArray[np.float64]
    sim: NDArray[np.float64]
    #: sig, sig_top, sig_original: (M,), (M,) and (n,) float32 significance of each row of base/top together, of top
    #: alone (for a contour drawn at t = 1) and of the original, EPSG:3857 metres (:mod:`engine.tiles.significance`): a
    #: tile whose grid unit is u skips rows below u / 2.
    sig: NDArray[np.float32]
    sig_top: NDArray[np.float32]
    sig_original: NDArray[np.float32]


@dataclass(frozen=True)
class ContourRecord(ContourColumns):
    """One stored contour, decoded: every array a tile or /simplify needs (the columns of
    :class:`ContourColumns`).
    """

    #: Stable integer id of the row (MVT feature id).
    fid: int

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        return int(self.base.nbytes + self.top.nbytes + self.original.nbytes + self.original_w.nbytes)


@dataclass(frozen=True)
class ContourHead:
    """The per-contour columns of a stored contour without its rows (see :class:`ContourRecord`)."""

    fid: int
    elevation: float
    vanish_scale: float
    t_at_scale: NDArray[np.float64]


@dataclass(frozen=True)
class StoredPieces:
    """Pieces of one kind of some contours' rows, concatenated: piece ``i`` is piece ``k[i]`` of contour
    ``fid[i]`` and holds ``n[i]`` rows of each column (:data:`~engine.store.schema.PIECE_KINDS`); piece k holds rows
    ``k * PIECE_ROWS`` to ``(k + 1) * PIECE_ROWS`` of its contour, both included (consecutive pieces share a row).
    """

    fid: NDArray[np.int64]
    k: NDArray[np.int64]
    n: NDArray[np.int64]
    columns: tuple[NDArray[Any], ...]


@dataclass(frozen=True)
class NewContour(ContourColumns):
    """One contour row to write: what :class:`ContourRecord` reads back, plus its R*Tree box.

    ``box`` is (minx, maxx, miny, maxy) in EPSG:3857 of every row the contour can draw; ``n_input`` is the
    number of input vertices.
    """

    n_input: int
    box: tuple[float, float, float, float]
    #: (step, reason) of each per-contour step the build could not finish (the contour is served without it).
    issues: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class LabelAnchors:
    """Placed labels, one entry each (arrays aligned)."""

    #: (n, 2) EPSG:3857 anchor points.
    xy: NDArray[np.float64]
    #: (n,) degrees for MapLibre's ``text-rotate``: clockwise, 0 = text runs west to east; in [-90, 90] when upright,
    #: else the text's top toward higher ground (docs/design.md section 9.3).
    angle: NDArray[np.float64]
    #: (n,) zoom from which the label is shown.
    min_zoom: NDArray[np.float64]
    #: fid, rank: (n,) contour of each label and its rank.
    fid: NDArray[np.int64]
    rank: NDArray[np.int64]
    #: (n,) its elevation.
    elevation: NDArray[np.float64]
    #: The label texts.
    text: list[str]
    #: (n, 2) width and height of each label's axis-aligned screen box (rotation included, padding included).
    box_px: NDArray[np.float64]
    #: (fid, reason) of each contour whose candidates could not be found: it is left without a label (not stored
    #: with the anchors: the build report keeps it, engine/store/issues.py).
    issues: tuple[tuple[int, str], ...] = ()

    def __len__(self) -> int:
        return len(self.fid)

    def select(self, keep: NDArray[np.bool_] | NDArray[np.intp]) -> LabelAnchors:
        """The labels chosen by a mask or positions."""
        pos = np.flatnonzero(keep) if np.asarray(keep).dtype == np.bool_ else np.asarray(keep)
        return LabelAnchors(
            self.xy[pos],
            self.angle[pos],
            self.min_zoom[pos],
            self.fid[pos],
            self.rank[pos],
            self.elevation[pos],
            [self.text[i] for i in pos.tolist()],
            self.box_px[pos],
        )


@dataclass(frozen=True)
class StoredLabels:
    """A dataset version's label anchors as stored, placed for zooms up to ``last_zoom``.

    Written with the contour rows (their fids are only known inside the write transaction), so a tile never
    places labels itself.
    """

    data_version: int
    last_zoom: float
    anchors: LabelAnchors


#: Places a dataset's labels once its rows and metadata are staged: called with the staged id, under which the
#: store's reads (``dataset``, ``load``, ...) see the new version before the switch makes it the dataset's.
LabelPlacer = Callable[[str], StoredLabels]


@dataclass(frozen=True)
class NewDataset:
    """A dataset's metadata to write beside its contour rows."""

    name: str
    source: str
    source_hash: str
    params: dict[str, Any]
    build_seconds: float
    working_crs: str
    source_crs: str
    interval: float | None
    source_scale: float
    target_scale: float
    ladder: NDArray[np.float64]
    bad_features: list[dict[str, Any]]
