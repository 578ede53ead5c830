"""A dataset version's label anchors: placed from its stored contours when the build writes them, and stored
with the version (docs/design.md section 9.3).

Placing the labels of a large dataset takes a minute or more; it depends only on the stored contours, their
metadata and the last zoom served, so the build does it once (on its staged rows, whose fids the dataset keeps,
before the switch that makes them the dataset's: no write transaction is open meanwhile) and a tile only reads
the result.
"""

from __future__ import annotations

import os
from concurrent.futures import Executor
from dataclasses import replace
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from engine.cartography.dataset import DatasetCartography, dataset_cartography, is_labelled, label_sources
from engine.cartography.labels import (
    CANDIDATE_BATCH,
    Candidates,
    LabelStyle,
    batch_candidates,
    orient_angle,
    place_among,
    place_labels,
)
from engine.cartography.neighbour_uphill import PROBE_M, top_uphill
from engine.errors import StoreError
from engine.intervals import infer_interval
from engine.parallel import map_ordered
from engine.payloads import FileUnreachable
from engine.store.records import ContourRecord, LabelAnchors, LabelPlacer, StoredLabels
from engine.store.store import CCSStore

#: The largest tile zoom served unless configured otherwise; builds place labels for it.
DEFAULT_MAX_ZOOM = 16
#: Contours read from the store at a time while label anchors are placed.
LABEL_BATCH = 512


def label_last_zoom(max_zoom: int) -> float:
    """The last zoom labels are checked at for a served maximum zoom: through the whole last level."""
    return float(max_zoom) + 1


def place_dataset_labels(
    store: CCSStore, dataset: str, max_zoom: int, executor: Executor | None = None
) -> StoredLabels:
    """Place the labels of the dataset's version as the store holds it, for tiles up to ``max_zoom``; the
    contours' candidates are found on ``executor`` (None: in this process, see :func:`place_labels`).

    Raises
    ------
    UnknownLayer
        The dataset is not stored.
    """
    info = store.dataset(dataset)
    fid, elevation, _, _ = store.dataset_heads(dataset)
    elevations = np.unique(elevation)  # the distinct levels, from the heads read for the fids anyway
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    # Only the labelled contours' rows are read (an index contour in five, at the default interval), a batch at
    # a time: placing keeps each one's candidates, not its rows.
    fids = fid[is_labelled(carto, elevation)].tolist()
    last_zoom = label_last_zoom(max_zoom)
    if executor is None:
        batches = (store.load(fids[k : k + LABEL_BATCH]) for k in range(0, len(fids), LABEL_BATCH))
        sources = (src for records in batches for src in label_sources(carto, records))
        anchors = place_labels(sources, info.ladder, carto.latitude, last_zoom)
    else:
        # The workers read the labelled contours' rows from the store themselves, as they wrote them: this
        # process only places the labels among the candidates that come back.
        style = LabelStyle()
        rows = StoredRows(str(store.path.resolve()), store.rows_id(dataset))
        tasks = (
            (rows, fids[k : k + CANDIDATE_BATCH], carto, info.ladder, last_zoom, style)
            for k in range(0, len(fids), CANDIDATE_BATCH)
        )
        found = map_ordered(executor, stored_candidates, tasks, refetch=partial(_with_rows, store))
        anchors = place_among((pair for batch in found for pair in batch), style)
    if carto.options.label_orientation == "uphill" and carto.uphill_side is None:
        anchors = uphill_from_neighbours(store, dataset, anchors)  # placed upright: the source gives no side
    return StoredLabels(info.data_version, last_zoom, anchors)


class StoredRows(NamedTuple):
    """Where a dataset's rows are, for a worker to read them itself: the store file and the rows' id."""

    path: str
    rows_id: str


class LabelSourceHead(NamedTuple):
    """What the placement reads of a labelled contour besides its candidates (a
    ``cartography.labels.LabelHead``), sent back by a worker instead of the contour's rows."""

    fid: int
    elevation: float
    text: str
    rank: int


#: The store files this process has opened to read label sources from, by path (a worker reads many batches).
_READING: dict[str, CCSStore] = {}


def stored_candidates(
    rows: StoredRows | list[ContourRecord],
    fids: list[int],
    carto: DatasetCartography,
    ladder: NDArray[np.float64],
    max_zoom: float,
    style: LabelStyle,
) -> list[tuple[LabelSourceHead, Candidates | str]]:
    """A task of a worker: the labelled contours ``fids`` read from the store (``rows``: where; or the rows
    themselves, read by the build process) and their label candidates, each with what the placement reads of
    it.

    Raises
    ------
    FileUnreachable
        This worker cannot read those rows there (another machine): the task goes again with the rows.
    """
    records = _stored_records(rows, fids) if isinstance(rows, StoredRows) else rows
    sources = label_sources(carto, records)
    found = batch_candidates(sources, ladder, carto.latitude, max_zoom, style)
    heads = [LabelSourceHead(s.fid, s.elevation, s.text, s.rank) for s in sources]
    return list(zip(heads, found, strict=True))


def _stored_records(rows: StoredRows, fids: list[int]) -> list[ContourRecord]:
    """The rows ``fids`` of ``rows`` read from its store file, all of them, or FileUnreachable."""
    records: list[ContourRecord] = []
    for fresh in (False, True):  # a file kept open from an earlier build may have been replaced since
        store = None if fresh else _READING.get(rows.path)
        try:
            if store is None:
                if not os.path.isfile(rows.path):
                    raise FileUnreachable(f"{rows.path}: no such file")
                store = _READING[rows.path] = CCSStore(rows.path, readonly=True)
            records = store.load(fids, rows.rows_id)
        except StoreError as exc:  # not a store: another file of that name
            raise FileUnreachable(f"{rows.path}: {exc}") from exc
        if len(records) == len(fids):
            return records
    raise FileUnreachable(f"{rows.path}: {len(fids) - len(records)} of the rows asked are not there")


def _with_rows(store: CCSStore, task: tuple[Any, ...]) -> tuple[Any, ...]:
    """A label task sent again when its worker cannot read the store: with the rows read here."""
    return (store.load(task[1]), *task[1:])


#: Labels whose neighbouring contours are read from the store at a time (near one another: sorted by cell).
ANCHORS_PER_QUERY = 256
#: Side of the cells (EPSG:3857 metres) labels are grouped by before they are taken ANCHORS_PER_QUERY at a time.
NEIGHBOUR_CELL_M = 20_000.0


def uphill_from_neighbours(store: CCSStore, dataset: str, anchors: LabelAnchors) -> LabelAnchors:
    """The labels, placed upright, each turned with its top toward higher ground where the neighbouring
    contours tell which side that is (:mod:`engine.cartography.neighbour_uphill`; past
    :data:`~engine.cartography.labels.UPSIDE_DOWN_LIMIT_DEG` from upright it stays upright). A half turn keeps
    a label's box, so the placement holds."""
    if not len(anchors.xy):
        return anchors
    angle = anchors.angle.copy()
    cell = np.floor(anchors.xy / NEIGHBOUR_CELL_M).astype(np.int64)
    order = np.lexsort((cell[:, 1], cell[:, 0]))
    for k in range(0, len(order), ANCHORS_PER_QUERY):
        idx = order[k : k + ANCHORS_PER_QUERY]
        lo, hi = anchors.xy[idx].min(axis=0) - PROBE_M, anchors.xy[idx].max(axis=0) + PROBE_M
        records = store.load(store.query(dataset, (lo[0], lo[1], hi[0], hi[1])))
        lines = [np.vstack([r.base, r.base[:1]]) if r.closed else r.base for r in records]
        heights = np.array([r.elevation for r in records], dtype=np.float64)
        signs = top_uphill(anchors.xy[idx], angle[idx], anchors.elevation[idx], lines, heights)
        a = np.radians(angle[idx])
        turned = angle[idx]
        for sign in (1, -1):  # the text reads along (cos a, -sin a), its top on that direction's left
            pick = signs == sign
            turned[pick] = orient_angle(np.cos(a[pick]), -np.sin(a[pick]), sign)
        angle[idx] = turned
    return replace(anchors, angle=angle)


def label_placer(store: CCSStore, max_zoom: int = DEFAULT_MAX_ZOOM, executor: Executor | None = None) -> LabelPlacer:
    """What :meth:`CCSStore.save` calls, with the id its rows are staged under, to place the labels of the
    version it writes (the candidates found on ``executor``, as the build's other work)."""
    return lambda staged: place_dataset_labels(store, staged, max_zoom, executor)
