"""A dataset version's label anchors: placed from its stored contours when the build writes them, and stored
with the version (docs/design.md section 9.3).

Placing the labels of a large dataset takes a minute or more; it depends only on the stored contours, their
metadata and the last zoom served, so the build does it once (on its staged rows, whose fids the dataset keeps,
before the switch that makes them the dataset's: no write transaction is open meanwhile) and a tile only reads
the result.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import replace

import numpy as np

from engine.cartography.dataset import dataset_cartography, is_labelled, label_sources
from engine.cartography.labels import orient_angle, place_labels
from engine.cartography.neighbour_uphill import PROBE_M, top_uphill
from engine.intervals import infer_interval
from engine.store.records import LabelAnchors, LabelPlacer, StoredLabels
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
    batches = (store.load(fids[k : k + LABEL_BATCH]) for k in range(0, len(fids), LABEL_BATCH))
    sources = (src for records in batches for src in label_sources(carto, records))
    last_zoom = label_last_zoom(max_zoom)
    anchors = place_labels(sources, info.ladder, carto.latitude, last_zoom, executor=executor)
    if carto.options.label_orientation == "uphill" and carto.uphill_side is None:
        anchors = uphill_from_neighbours(store, dataset, anchors)  # placed upright: the source gives no side
    return StoredLabels(info.data_version, last_zoom, anchors)


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
