"""Contours packed into a few big arrays, so that a tile is a handful of NumPy calls plus one compiled pass.

A :class:`LineSet` is many lines' rows concatenated, with each line's chunk boxes (its own spatial index) and
row significance; a :class:`DatasetPack` holds a dataset version's contours as two line sets (the CCS rows
and the input contours) plus their per-contour columns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from engine.intervals import is_index
from engine.store.records import ContourRecord
from engine.tiles.runs import CHUNK_ROWS, chunk_bounds_packed

#: Bytes per stored vertex a dataset pack holds, about (to decide whether a dataset fits the contour memory).
PACK_BYTES_PER_VERTEX = 120


@dataclass(frozen=True)
class LineSet:
    """The rows of many lines concatenated: line i is rows [off[i], off[i + 1]) of ``base`` and ``top``.

    A line is drawn at t as ``(1 - t) base + t top``; a line that does not morph has ``top is base``.
    """

    #: base, top: (M, 2) EPSG:3857 rows.
    base: NDArray[np.float64]
    top: NDArray[np.float64]
    #: (n + 1,) row offsets.
    off: NDArray[np.int64]
    #: (M, k) float32 significance of each row; a tile chooses one column per line.
    sig: NDArray[np.float32]
    #: chunk_off, chunks: (n + 1,) offsets into (C, 4) (minx, miny, maxx, maxy) boxes of each line's runs of
    #: ``chunk_rows`` rows (boxes over both ``base`` and ``top``, so a slice at any t lies inside them).
    chunk_off: NDArray[np.int64]
    chunks: NDArray[np.float64]
    chunk_rows: int = CHUNK_ROWS

    @classmethod
    def of(
        cls,
        base: NDArray[np.float64],
        top: NDArray[np.float64],
        sizes: Sequence[int] | NDArray[np.int64],
        sig: NDArray[np.float32],
        chunk_rows: int = CHUNK_ROWS,
    ) -> LineSet:
        """Offsets and chunk boxes of concatenated lines."""
        off = np.concatenate([[0], np.cumsum(np.asarray(sizes, dtype=np.int64))]).astype(np.int64)
        sig2 = np.ascontiguousarray(sig.reshape(len(base), -1), dtype=np.float32)
        if len(sizes) == 0:
            return cls(base, top, off, sig2, np.zeros(1, np.int64), np.zeros((0, 4)), chunk_rows)
        rows = [base] if top is base else [base, top]
        chunks, chunk_off = chunk_bounds_packed(rows, off, chunk_rows)
        return cls(base, top, off, sig2, chunk_off, chunks, chunk_rows)

    @classmethod
    def fixed(cls, lines: Sequence[NDArray[np.float64]]) -> LineSet:
        """Lines drawn as they are, every row kept, one chunk per line (a tile takes each line whole)."""
        sizes = [len(v) for v in lines]
        base = np.ascontiguousarray(np.concatenate(lines)) if lines else np.zeros((0, 2))
        keep_all = np.full(len(base), np.inf, dtype=np.float32)
        return cls.of(base, base, sizes, keep_all, chunk_rows=max([*sizes, 2]))

    @property
    def nbytes(self) -> int:
        """Memory held."""
        arrays: list[NDArray[Any]] = [self.base, self.off, self.sig, self.chunk_off, self.chunks]
        if self.top is not self.base:
            arrays.append(self.top)
        return int(sum(a.nbytes for a in arrays))


class ContourColumns(Protocol):
    """The per-contour columns a pack holds (a :class:`ContourRecord` or a stored contour's head)."""

    @property
    def fid(self) -> int:
        """Feature id."""

    @property
    def elevation(self) -> float:
        """Height of the contour."""

    @property
    def vanish_scale(self) -> float:
        """Scale denominator from which on the contour is not drawn (inf: never vanishes)."""

    @property
    def t_at_scale(self) -> NDArray[np.float64]:
        """t at each scale of the dataset's ladder."""


@dataclass(frozen=True)
class HeadColumns:
    """Per-contour columns of some contours, in fid order (what a pack holds of each contour besides its rows)."""

    #: fid, elevation, vanish: (n,) feature ids (ascending), heights and vanishing scales (inf: never vanishes).
    fid: NDArray[np.int64]
    elevation: NDArray[np.float64]
    vanish: NDArray[np.float64]
    #: (n, S) t at each scale of the dataset's ladder.
    tables: NDArray[np.float64]

    @classmethod
    def of(cls, heads: Sequence[ContourColumns]) -> HeadColumns:
        """The columns of contours (in fid order)."""
        return cls(
            np.array([h.fid for h in heads], dtype=np.int64),
            np.array([float(h.elevation) for h in heads], dtype=np.float64),
            np.array([h.vanish_scale for h in heads], dtype=np.float64),
            np.stack([h.t_at_scale for h in heads]) if heads else np.zeros((0, 1)),
        )

    @property
    def nbytes(self) -> int:
        """Memory held."""
        return int(self.fid.nbytes + self.elevation.nbytes + self.vanish.nbytes + self.tables.nbytes)

    def take(self, pos: NDArray[np.intp]) -> HeadColumns:
        """The heads at positions ``pos``."""
        return HeadColumns(self.fid[pos], self.elevation[pos], self.vanish[pos], self.tables[pos])

    def locate(self, fids: Sequence[int] | NDArray[np.int64]) -> NDArray[np.intp] | None:
        """Positions of ``fids`` (sorted); None when one of them is not here (a version written since)."""
        f = np.asarray(fids, dtype=np.int64)
        if len(self.fid) == 0:
            return None if len(f) else np.zeros(0, dtype=np.intp)
        pos = np.minimum(np.searchsorted(self.fid, f), len(self.fid) - 1)
        return pos if bool((self.fid[pos] == f).all()) else None


@dataclass(frozen=True)
class CCSRows:
    """A contour's CCS rows (or a stretch of them) and their significance: together, and of ``top`` alone."""

    base: NDArray[np.float64]
    top: NDArray[np.float64]
    sig: NDArray[np.float32]
    sig_top: NDArray[np.float32]


@dataclass(frozen=True)
class OriginalRows:
    """A contour's input rows (or a stretch of them) and their significance."""

    rows: NDArray[np.float64]
    sig: NDArray[np.float32]


@dataclass(frozen=True)
class DatasetPack:
    """Contours of one dataset version (in fid order) in a few big arrays.

    ``ccs`` holds the CCS rows; its significance has two columns: of the (base, top) rows together (valid at
    every t) and of ``top`` alone (for contours drawn at t = 1). ``original`` holds the input contours.
    """

    data_version: int
    fid: NDArray[np.int64]
    vanish: NDArray[np.float64]
    elevation: NDArray[np.float64]
    index: NDArray[np.bool_]
    tables: NDArray[np.float64]
    ccs: LineSet
    original: LineSet

    @classmethod
    def of(cls, data_version: int, recs: Sequence[ContourRecord], interval: float | None) -> DatasetPack:
        """Pack decoded contour rows (in fid order)."""
        ccs = [CCSRows(r.base, r.top, r.sig, r.sig_top) for r in recs]
        original = [OriginalRows(r.original, r.sig_original) for r in recs]
        return cls.of_rows(data_version, recs, ccs, original, interval)

    @classmethod
    def of_rows(
        cls,
        data_version: int,
        heads: Sequence[ContourColumns],
        ccs: Sequence[CCSRows],
        original: Sequence[OriginalRows],
        interval: float | None,
    ) -> DatasetPack:
        """Pack contours (in fid order) from their columns and rows (whole, or the stretch a tile meets)."""
        z2 = np.zeros((0, 2))
        base = np.ascontiguousarray(np.concatenate([c.base for c in ccs])) if ccs else z2
        top = np.ascontiguousarray(np.concatenate([c.top for c in ccs])) if ccs else z2
        orig = np.ascontiguousarray(np.concatenate([o.rows for o in original])) if original else z2
        ccs_sig = np.zeros((0, 2), np.float32)
        orig_sig = np.zeros(0, np.float32)
        if ccs:
            sig = np.concatenate([c.sig for c in ccs])
            ccs_sig = np.column_stack([sig, np.concatenate([c.sig_top for c in ccs])]).astype(np.float32)
            orig_sig = np.concatenate([o.sig for o in original]).astype(np.float32)
        ccs_lines = LineSet.of(base, top, [len(c.base) for c in ccs], ccs_sig)
        original_lines = LineSet.of(orig, orig, [len(o.rows) for o in original], orig_sig)
        return cls.of_lines(data_version, HeadColumns.of(heads), ccs_lines, original_lines, interval)

    @classmethod
    def of_lines(
        cls,
        data_version: int,
        heads: HeadColumns,
        ccs: LineSet,
        original: LineSet,
        interval: float | None,
    ) -> DatasetPack:
        """Pack contours (in fid order) from their columns and their two line sets (one line per contour)."""
        values, inverse = np.unique(heads.elevation, return_inverse=True)
        index_of = np.array([is_index(float(e), interval) for e in values], dtype=bool)
        return cls(
            data_version, heads.fid, heads.vanish, heads.elevation, index_of[inverse], heads.tables, ccs, original
        )

    @property
    def nbytes(self) -> int:
        """Memory held."""
        arrays = (self.fid, self.vanish, self.elevation, self.index, self.tables)
        return int(sum(a.nbytes for a in arrays) + self.ccs.nbytes + self.original.nbytes)

    def locate(self, fids: Sequence[int]) -> NDArray[np.intp] | None:
        """Positions of fids (sorted) in the pack; None when one of them is not in it (another version)."""
        f = np.asarray(fids, dtype=np.int64)
        if len(self.fid) == 0:
            return None if len(f) else np.zeros(0, dtype=np.intp)
        pos = np.minimum(np.searchsorted(self.fid, f), len(self.fid) - 1)
        return pos if bool((self.fid[pos] == f).all()) else None
