"""What the server knows of each stored dataset's current version: its metadata, cartography, pack, heads and
decoded rows, each read or made once per data version; and the contours a tile's box meets, packed.

A dataset that fits the contour memory is held as one :class:`~engine.serve.pack.DatasetPack` (built once per
data version); a larger one is packed per request from the stretches of the touched contours' rows that meet the
tile, read from their stored pieces (:mod:`engine.serve.pieces`; the same tiles, about the same work).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from engine.cartography.dataset import DatasetCartography, dataset_cartography
from engine.intervals import infer_interval
from engine.serve.cache import LRUCache
from engine.serve.heads import DEFAULT_HEAD_CACHE_BYTES, DatasetHeads, head_bytes
from engine.serve.pack import PACK_BYTES_PER_VERTEX, DatasetPack
from engine.serve.pieces import pack_of_pieces
from engine.store.records import ContourRecord, DatasetInfo
from engine.store.store import CCSStore
from engine.types import Bounds


class DatasetView:
    """The store's datasets as tiles read them, cached per data version.

    Parameters
    ----------
    store
        The store to read.
    contour_cache_bytes
        Memory for decoded contour rows and dataset packs.
    head_cache_bytes
        Memory for the contour heads of datasets too large to pack, all datasets together
        (:mod:`engine.serve.heads`); a dataset whose heads do not fit reads each tile's from the store.
    """

    def __init__(
        self, store: CCSStore, contour_cache_bytes: int = 512 << 20, head_cache_bytes: int = DEFAULT_HEAD_CACHE_BYTES
    ) -> None:
        self.store = store
        self.contours: LRUCache[int, ContourRecord] = LRUCache(contour_cache_bytes, lambda r: r.nbytes + 1024)
        self.contour_cache_bytes = contour_cache_bytes
        self.head_cache_bytes = head_cache_bytes
        self._heads: dict[str, DatasetHeads] = {}
        self._info: dict[str, tuple[DatasetInfo, float | None]] = {}
        self._packs: dict[str, DatasetPack] = {}
        self._cartography: dict[str, tuple[int, DatasetCartography]] = {}
        self._pack_lock = threading.Lock()
        self._forget_too: list[Callable[[str], None]] = []

    def also_forget(self, forget: Callable[[str], None]) -> None:
        """Call ``forget(dataset)`` whenever this view forgets a dataset (for caches kept beside it)."""
        self._forget_too.append(forget)

    def info(self, dataset: str) -> tuple[DatasetInfo, float | None]:
        """The dataset's metadata and contour interval (stored, else inferred), cached per data_version.

        Raises
        ------
        UnknownLayer
            The dataset is not stored.
        """
        version = self.store.data_version(dataset)
        cached = self._info.get(dataset)
        if cached is not None and version is not None and cached[0].data_version == version:
            return cached
        info = self.store.dataset(dataset)
        interval = info.interval or infer_interval(self.store.elevations(dataset))
        self._info[dataset] = (info, interval)
        return info, interval

    def forget(self, dataset: str) -> None:
        """Drop cached metadata of a dataset (after a delete or rebuild; contour rows get new fids anyway)."""
        self._info.pop(dataset, None)
        self._packs.pop(dataset, None)
        self._heads.pop(dataset, None)
        self._cartography.pop(dataset, None)
        for forget in self._forget_too:
            forget(dataset)

    def cartography(self, dataset: str) -> DatasetCartography:
        """The dataset's options, interval schedule and label anchors, made once per data version
        (docs/design.md section 9)."""
        info, interval = self.info(dataset)
        cached = self._cartography.get(dataset)
        if cached is not None and cached[0] == info.data_version:
            return cached[1]
        carto = dataset_cartography(info, interval, self.store.elevations(dataset))
        self._cartography[dataset] = (info.data_version, carto)
        return carto

    def pack(self, dataset: str) -> DatasetPack | None:
        """The dataset's contours packed (built once per data version), or None when the dataset is larger
        than the contour memory."""
        info, interval = self.info(dataset)
        pack = self._packs.get(dataset)
        if pack is not None and pack.data_version == info.data_version:
            return pack
        if info.n_vertices * PACK_BYTES_PER_VERTEX > self.contour_cache_bytes:
            return None
        with self._pack_lock:
            pack = self._packs.get(dataset)
            if pack is None or pack.data_version != info.data_version:
                recs = self.store.load(self.store.all_fids(dataset))
                pack = DatasetPack.of(info.data_version, recs, interval)
                self._packs[dataset] = pack
        return pack

    def heads(self, dataset: str) -> DatasetHeads | None:
        """Every contour head of the dataset's version (read once per data version), or None when they do not
        fit in the head memory beside the other datasets' heads held."""
        info, _ = self.info(dataset)
        held = self._heads.get(dataset)
        if held is not None and held.data_version == info.data_version:
            return held
        with self._pack_lock:
            held = self._heads.pop(dataset, None)
            if held is not None and held.data_version == info.data_version:
                self._heads[dataset] = held  # read by another thread meanwhile
                return held
            others = sum(h.heads.nbytes for h in self._heads.values())
            if others + head_bytes(info.n_contours, len(info.ladder)) > self.head_cache_bytes:
                return None
            held = DatasetHeads.read(self.store, dataset, info.data_version)
            self._heads[dataset] = held
        return held

    def records(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decoded contour rows, from the cache or the store, in the order given (unknown fids skipped)."""
        out: list[ContourRecord | None] = [self.contours.get(f) for f in fids]
        missing = [f for f, r in zip(fids, out, strict=True) if r is None]
        if missing:
            loaded = {r.fid: r for r in self.store.load(missing)}
            for f, r in loaded.items():
                self.contours.put(f, r)
            out = [r if r is not None else loaded.get(f) for f, r in zip(fids, out, strict=True)]
        return [r for r in out if r is not None]

    def packed(self, dataset: str, box: Bounds, rows: str | None) -> tuple[DatasetPack, NDArray[np.intp]] | None:
        """The contours a tile's buffered ``box`` meets, in a pack, and their positions in it; None when there
        is none.

        The pack is the dataset's, or one of just the pieces of the contours' ``rows`` (``ccs``, ``original``, or
        None for the baselines, which draw from whole decoded contours) that meet ``box``
        (:mod:`engine.serve.pieces`).
        """
        pack = self.pack(dataset)
        if pack is not None:
            fids = self.store.query(dataset, box)
            if not fids:
                return None
            where = pack.locate(fids)
            if where is None:  # the store changed under the pack: take the new version
                self.forget(dataset)
                pack = self.pack(dataset)
                where = pack.locate(fids) if pack is not None else None
            if pack is not None and where is not None:
                return pack, where
        info, interval = self.info(dataset)
        part = pack_of_pieces(self.store, dataset, box, info.data_version, interval, rows, self.heads(dataset))
        return None if part is None or len(part.fid) == 0 else (part, np.arange(len(part.fid)))
