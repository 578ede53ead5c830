"""A dataset version's label anchors: placed from its stored contours when the build writes them, and stored
with the version (docs/design.md section 9.3).

Placing the labels of a large dataset takes a minute or more; it depends only on the stored contours, their
metadata and the last zoom served, so the build does it once (on its staged rows, whose fids the dataset keeps,
before the switch that makes them the dataset's: no write transaction is open meanwhile) and a tile only reads
the result.
"""

from __future__ import annotations

from concurrent.futures import Executor

from engine.cartography.dataset import dataset_cartography, label_sources
from engine.cartography.labels import place_labels
from engine.intervals import infer_interval
from engine.store.records import LabelPlacer, StoredLabels
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
    elevations = store.elevations(dataset)
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    fids = store.all_fids(dataset)
    # A batch of contours at a time: placing keeps each one's candidates, not its rows.
    batches = (store.load(fids[k : k + LABEL_BATCH]) for k in range(0, len(fids), LABEL_BATCH))
    sources = (src for records in batches for src in label_sources(carto, records))
    last_zoom = label_last_zoom(max_zoom)
    anchors = place_labels(sources, info.ladder, carto.latitude, last_zoom, executor=executor)
    return StoredLabels(info.data_version, last_zoom, anchors)


def label_placer(
    store: CCSStore, max_zoom: int = DEFAULT_MAX_ZOOM, executor: Executor | None = None
) -> LabelPlacer:
    """What :meth:`CCSStore.save` calls, with the id its rows are staged under, to place the labels of the
    version it writes (the candidates found on ``executor``, as the build's other work)."""
    return lambda staged: place_dataset_labels(store, staged, max_zoom, executor)

