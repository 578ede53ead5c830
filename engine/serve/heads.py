"""Every contour's head of a dataset version held in memory: the per-contour columns a tile of stored pieces needs
(fid, elevation, vanishing scale, t table), so a tile does not read them from the store.

A tile of a dataset too large to pack whole touches hundreds of contours, and reading their heads took about a
tenth of a tile at 64× the sample (one store row each, scattered over the file). The heads of a whole version
are read at once instead, in fid order, into four arrays: 8 × (S + 3) bytes per contour for a ladder of S
scales, 55 MB for the 193,000 contours of 64× the sample (S = 33). A renderer holds them only while they fit
its head memory (``head_cache_bytes``); a dataset beyond it reads each tile's heads as before.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from engine.serve.pack import HeadColumns
from engine.store.store import CCSStore

#: Head memory of a renderer unless configured: the heads of about 450,000 contours with a ladder of 33 scales.
DEFAULT_HEAD_CACHE_BYTES = 128 << 20


def head_bytes(n_contours: int, ladder_size: int) -> int:
    """Memory the heads of ``n_contours`` contours take, with t tables of ``ladder_size`` scales."""
    return 8 * (ladder_size + 3) * n_contours


def read_heads(store: CCSStore, fids: Sequence[int]) -> HeadColumns:
    """The heads of contours ``fids`` (sorted) read from the store (unknown fids skipped)."""
    return HeadColumns.of(store.load_heads(fids))


@dataclass(frozen=True)
class DatasetHeads:
    """Every head of one version of a dataset."""

    data_version: int
    heads: HeadColumns

    @classmethod
    def read(cls, store: CCSStore, dataset: str, data_version: int) -> DatasetHeads:
        """All the dataset's heads as the store holds them now, for ``data_version``."""
        fid, elevation, vanish, tables = store.dataset_heads(dataset)
        return cls(data_version, HeadColumns(fid, elevation, vanish, tables))

    @property
    def fid_range(self) -> tuple[int, int] | None:
        """(first, last) when the dataset's fids are every fid from first to last (a dataset is saved in one
        transaction, its fids counted up one by one), else None."""
        fid = self.heads.fid
        if len(fid) == 0 or int(fid[-1]) - int(fid[0]) + 1 != len(fid):
            return None
        return int(fid[0]), int(fid[-1])

    def of(self, store: CCSStore, fids: Sequence[int]) -> HeadColumns:
        """The heads of ``fids`` (sorted): from memory, or from the store when one is not held (the store
        changed since these were read; the renderer reads the new version's on its next tile)."""
        pos = self.heads.locate(fids)
        return read_heads(store, fids) if pos is None else self.heads.take(pos)
