"""The store: precomputed CCS rows, Sim(t) and t(scale) tables and dataset metadata in one SQLite file.

Persistence only: the rows arrive ready (reprojected, with their significance; :mod:`engine.build.records`)
and leave decoded; what they mean is the serving layer's business.

- Contour extents sit in an R*Tree (EPSG:3857), so a tile looks up only the contours it touches.
- A dataset's rows are written in bounded transactions under a private id and made its new version by **one
  short switch** (:mod:`engine.store.staging`): no write waits on a build, and a build killed at any moment
  leaves the previous content as it was (its staged rows are removed later).
- Each dataset records the content hash of its source and build parameters, so a changed source is rebuilt
  and an unchanged one is served at once after a restart.

The file's tables are :mod:`engine.store.schema`, its connections :mod:`engine.store.connection`, the records
:mod:`engine.store.records` and their bytes :mod:`engine.store.codec`; the builds recorded beside the
datasets are :mod:`engine.store.builds`.
"""

from __future__ import annotations

import secrets
import sqlite3
import time
from collections.abc import Callable, Iterable, Sequence
from itertools import chain
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from engine.errors import BuildCancelled, StoreError, UnknownLayer
from engine.store.builds import BuildBook, forget_build, has_build, is_building
from engine.store.codec import (
    CONTOUR_COLUMNS,
    HEAD_COLUMNS,
    LABEL_COLUMNS,
    RowTally,
    contour_head,
    contour_record,
    dataset_info,
    dataset_row,
    label_row,
    piece_column,
    stored_labels,
    vanish_value,
)
from engine.store.issues import REPORTED_ISSUES, insert_issues, read_issues
from engine.store.records import (
    ContourHead,
    ContourRecord,
    DatasetInfo,
    LabelPlacer,
    NewDataset,
    StoredLabels,
    StoredPieces,
)
from engine.store.schema import PIECE_KINDS
from engine.store.shard import MergedShard, Shard, StageTarget, merge_shard
from engine.store.staging import (
    drop_reservation,
    is_private,
    leftover_ids,
    owner_of,
    purge_some,
    reserve_fids,
    row_ids,
    staging_id,
)

T = TypeVar("T")

#: What a save is given to write a dataset's rows: told where they go, the shards in the build's order, each
#: merged already by its worker or to be merged by the build process (:mod:`engine.store.shard`).
ShardWriter = Callable[[StageTarget], Iterable[Shard | MergedShard]]


def pieces_sql(kind: str, by_fid: bool) -> str:
    """The query of :meth:`CCSStore.pieces_meeting`: pieces of ``kind`` whose box meets (minx, maxx, miny, maxy),
    of one dataset (its id; ``by_fid``: its first and last fid).

    The R*Tree is searched first: ``+p.fid`` keeps SQLite from walking the pieces' fid index over the whole
    dataset instead (a hundred times slower at 64× the sample)."""
    columns = ", ".join(f"p.{c}" for c in PIECE_KINDS[kind])
    ours = "+p.fid BETWEEN ? AND ?" if by_fid else "r.dataset = ?"
    return (
        f"SELECT p.fid, p.k, {columns} FROM {kind}_piece_rtree r JOIN {kind}_pieces p ON p.piece = r.piece "
        f"WHERE r.maxx >= ? AND r.minx <= ? AND r.maxy >= ? AND r.miny <= ? AND {ours}"
    )


class CCSStore(BuildBook):
    """One SQLite store file of built datasets (and of the builds under way, :class:`BuildBook`).
    Thread-safe: each thread gets its own connection. It is opened as a
    :class:`~engine.store.connection.StoreFile` is (the same parameters ``path``, ``readonly`` and ``mmap_bytes``,
    and the same :class:`~engine.errors.StoreError` when the file cannot serve as a store).
    """

    # -- datasets ----------------------------------------------------------------------------------------
    def dataset_ids(self) -> list[str]:
        """Ids of the stored (ready) datasets, sorted (a build's staged row is none)."""
        return [r[0] for r in self._con().execute("SELECT id FROM datasets ORDER BY id") if not is_private(r[0])]

    def data_version(self, dataset: str) -> int | None:
        """The dataset's current data_version, or None if it is not stored."""
        row = self._con().execute("SELECT data_version FROM datasets WHERE id=?", (dataset,)).fetchone()
        return None if row is None else int(row[0])

    def source_hash_of(self, dataset: str) -> str | None:
        """The stored source hash of a dataset, or None."""
        row = self._con().execute("SELECT source_hash FROM datasets WHERE id=?", (dataset,)).fetchone()
        return None if row is None else str(row[0])

    def dataset(self, dataset: str) -> DatasetInfo:
        """Metadata of a stored dataset.

        Raises
        ------
        UnknownLayer
            No dataset of that id is stored.
        """
        con = self._con()
        con.row_factory = sqlite3.Row
        try:
            row = con.execute("SELECT * FROM datasets WHERE id=?", (dataset,)).fetchone()
        finally:
            con.row_factory = None
        if row is None:
            raise UnknownLayer(f"unknown dataset {dataset!r}")
        return dataset_info(row)

    def save(
        self,
        dataset: str,
        meta: NewDataset,
        shards: ShardWriter,
        count: int,
        progress: Callable[[int, int], None] | None = None,
        *,
        only_if_building: bool = False,
        labels: LabelPlacer | None = None,
    ) -> DatasetInfo:
        """Write a dataset of ``count`` contours, replacing any previous version: staged in bounded
        transactions, then one switch.

        ``count`` fids are reserved first, and the rows come in shards (:mod:`engine.store.shard`, written where
        the rows were made): ``shards`` is told where they go (:class:`StageTarget`) and yields them in the
        build's order (a generator keeps only a few in memory). A shard its worker merged is only counted here;
        any other is merged here. Each merge writes at most :data:`~engine.store.shard.STAGE_CONTOURS` contours
        or :data:`~engine.store.shard.STAGE_ROWS` rows per transaction, under the dataset's staged id
        (:mod:`engine.store.staging`): other writes wait at most one such step, readers see nothing of it. The
        dataset's row goes in last; ``labels``, when given, is called with the staged id (its rows and row are
        readable under it) and returns the anchors. The switch is one short transaction that rewrites no contour
        row: the old version's row and labels out, the staged row made the dataset's (it names the staged rows),
        its labels and new ``data_version`` in; the replaced version's rows are then removed a few at a time.
        An exception (or a killed process) before the switch
        leaves the previous version as it was and its staged rows to be removed. With ``only_if_building``
        every transaction checks that the dataset's build is still recorded, the switch too, so a dataset
        deleted during its build never comes back: BuildCancelled is raised instead. ``progress`` gets
        (contours written, contours written).
        """
        stage = staging_id(dataset, self._stored_rows_id(dataset))
        self.purge(stage)  # what a killed build of this id left
        try:
            target = self._reserve(dataset, stage, count, only_if_building)
            counts = self._stage_shards(target, shards(target), progress)
            if counts.n != count:
                raise StoreError(f"dataset {dataset!r}: {counts.n} contours written, {count} expected")
            with self._write() as cur:
                self._check_building(cur, dataset, only_if_building)
                cur.execute(
                    "INSERT INTO datasets VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    dataset_row(stage, meta, 0, time.time(), counts),
                )
            placed = labels(stage) if labels is not None else None
            with self._write() as cur:
                self._check_building(cur, dataset, only_if_building)
                replaced = self._switch(cur, dataset, stage, placed)
        except BaseException:
            self._purge_quietly(stage)
            raise
        if replaced is not None:
            self._purge_quietly(replaced)
        return self.dataset(dataset)

    @staticmethod
    def _check_building(cur: sqlite3.Cursor, dataset: str, only_if_building: bool) -> None:
        if only_if_building and not is_building(cur, dataset):
            raise BuildCancelled(f"dataset {dataset!r} was deleted while it built")

    def _reserve(self, dataset: str, stage: str, count: int, only_if_building: bool) -> StageTarget:
        """Reserve the fids of a build's ``count`` rows staged under ``stage``: where its tasks write them."""
        token = secrets.token_hex(16)
        with self._write() as cur:
            self._check_building(cur, dataset, only_if_building)
            first = reserve_fids(cur, stage, count, token)
        return StageTarget(str(self.path.resolve()), dataset, stage, first, token, only_if_building)

    def _stage_shards(
        self, target: StageTarget, shards: Iterable[Shard | MergedShard], progress: Callable[[int, int], None] | None
    ) -> RowTally:
        """Count the shards as they come, in the build's order, and merge here those their workers did not."""
        counts = RowTally()
        for shard in shards:
            if isinstance(shard, Shard) and not merge_shard(self, target, shard, counts.n):
                raise StoreError(f"dataset {target.dataset!r}: its build's reservation of fids was dropped")
            counts.merge(shard.tally)
            if progress:
                progress(counts.n, counts.n)
        return counts

    @classmethod
    def _switch(cls, cur: sqlite3.Cursor, dataset: str, stage: str, placed: StoredLabels | None) -> str | None:
        """The one short transaction that makes the staged rows the dataset's new version: its row points at
        them, no contour row is rewritten. The row id of the version replaced (its rows to remove), or None."""
        replaced = cls._retire(cur, dataset)
        if replaced == stage:
            raise StoreError(f"dataset {dataset!r} was replaced by another build meanwhile")
        counter = int(cur.execute("SELECT value FROM store_meta WHERE key='version_counter'").fetchone()[0]) + 1
        cur.execute("UPDATE store_meta SET value=? WHERE key='version_counter'", (str(counter),))
        cur.execute(
            "UPDATE datasets SET id=?, data_version=?, built_at=? WHERE id=?", (dataset, counter, time.time(), stage)
        )
        if placed is not None:
            cur.execute("INSERT INTO labels VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", label_row(dataset, counter, placed))
            for label_fid, reason in placed.anchors.issues:
                insert_issues(cur, stage, label_fid, [("labels", reason)])
        forget_build(cur, dataset)
        drop_reservation(cur, stage)
        return replaced

    @staticmethod
    def _retire(cur: sqlite3.Cursor, dataset: str) -> str | None:
        """Take a dataset's version out of sight: its row and labels gone. The row id its contour rows and
        issues wait under to be removed (by :meth:`purge`), or None when it was not stored."""
        row = cur.execute("SELECT rows_id FROM datasets WHERE id=?", (dataset,)).fetchone()
        cur.execute("DELETE FROM datasets WHERE id=?", (dataset,))
        cur.execute("DELETE FROM labels WHERE dataset=?", (dataset,))
        return None if row is None else str(row[0])

    def _stored_rows_id(self, dataset: str) -> str | None:
        """The row id a stored dataset's rows are under (None: not stored)."""
        row = self._con().execute("SELECT rows_id FROM datasets WHERE id=?", (dataset,)).fetchone()
        return None if row is None else str(row[0])

    def rows_id(self, dataset: str) -> str:
        """The id a dataset's contour rows are stored under (a staged build's dataset row is its own; an
        unknown dataset's own id, under which no row is stored): what :meth:`load` takes to read only its rows."""
        return self._rows_of(dataset)

    def _rows_of(self, dataset: str) -> str:
        """The id to read a dataset's rows by: its row id (a staged build's dataset row is its own); an unknown
        dataset's own id, under which no row is stored."""
        return self._stored_rows_id(dataset) or dataset

    def purge(self, ident: str) -> None:
        """Remove every row of a private id (:mod:`engine.store.staging`), a few contours per transaction."""
        while True:
            with self._write() as cur:
                if purge_some(cur, ident) == 0:
                    return

    def _purge_quietly(self, ident: str) -> None:
        try:
            self.purge(ident)
        except StoreError:
            pass  # a full disk or a busy store: the next build of this id or the next start removes them

    def purge_leftovers(self) -> list[str]:
        """Remove the rows of builds no longer running and of versions replaced or deleted (at a start);
        the private ids removed. A staged id whose build is recorded as running (its process alive) is kept."""
        running = {d for d, s in self.build_statuses().items() if s.state == "building"}
        removed = []
        for ident in leftover_ids(self._con()):
            if owner_of(ident) in running:
                continue
            self._purge_quietly(ident)
            removed.append(ident)
        return removed

    def labels(self, dataset: str) -> StoredLabels | None:
        """The label anchors stored with the dataset's current version, or None (none were placed at build)."""
        row = self._con().execute(f"SELECT {LABEL_COLUMNS} FROM labels WHERE dataset=?", (dataset,)).fetchone()
        return None if row is None else stored_labels(row)

    def contour_issues(self, dataset: str, limit: int = REPORTED_ISSUES) -> tuple[list[dict[str, Any]], int]:
        """The dataset's contours served without part of their build (``fid``, ``id``, ``step``, ``reason``;
        the first ``limit``) and how many there are."""
        return read_issues(self._con(), self._rows_of(dataset), limit)

    def delete(self, dataset: str) -> bool:
        """Remove a dataset and its build status; True if it was stored."""
        return self._delete(dataset)[0]

    def delete_any(self, dataset: str) -> bool:
        """Remove a dataset, stored or only building or failed; True if there was either."""
        stored, build = self._delete(dataset)
        return stored or build

    def _delete(self, dataset: str) -> tuple[bool, bool]:
        """One short transaction takes the dataset out of sight and forgets its build (a build still running
        can no longer write it); its rows, and what its build staged, are then removed a few at a time.
        (stored, had a build)."""
        with self._write() as cur:
            build = has_build(cur, dataset)
            replaced = self._retire(cur, dataset)
            forget_build(cur, dataset)
        for ident in {replaced, *row_ids(dataset)} - {None}:  # its rows, and what a build of it staged
            self._purge_quietly(str(ident))
        return replaced is not None, build

    # -- contours ----------------------------------------------------------------------------------------
    def query(self, dataset: str, bounds_3857: Sequence[float]) -> list[int]:
        """fids of the dataset's contours whose extent meets an EPSG:3857 rectangle (R*Tree lookup)."""
        minx, miny, maxx, maxy = (float(v) for v in bounds_3857)
        # The dataset is an auxiliary column of the R*Tree: filtered after the spatial search, so the cost
        # follows the contours near the rectangle, not the size of the store.
        cur = self._con().execute(
            "SELECT fid FROM contour_rtree WHERE maxx >= ? AND minx <= ? AND maxy >= ? AND miny <= ? "
            "AND dataset = ? ORDER BY fid",
            (minx, maxx, miny, maxy, self._rows_of(dataset)),
        )
        return list(chain.from_iterable(cur))

    def pieces_meeting(
        self, dataset: str, bounds_3857: Sequence[float], kind: str, fid_range: tuple[int, int] | None = None
    ) -> StoredPieces:
        """The dataset's pieces of one kind (``ccs`` or ``original``) whose rows' extent meets an EPSG:3857
        rectangle, sorted by fid and k.

        ``fid_range`` (first, last): the dataset's contours are exactly the fids first to last, so its pieces
        are told apart by their fid instead of the R*Tree's dataset column, which costs a look-up of every
        candidate in the R*Tree's own row table (a quarter of the query at 64× the sample).
        """
        minx, miny, maxx, maxy = (float(v) for v in bounds_3857)
        names = PIECE_KINDS[kind]
        mine = fid_range if fid_range is not None else (self._rows_of(dataset),)
        rows = self._con().execute(pieces_sql(kind, fid_range is not None), (minx, maxx, miny, maxy, *mine)).fetchall()
        # Sorted here, not by SQL's ORDER BY, whose sorter copies every row with its blobs.
        fid = np.array([r[0] for r in rows], dtype=np.int64)
        k = np.array([r[1] for r in rows], dtype=np.int64)
        order = np.lexsort((k, fid))
        rows = [rows[i] for i in order.tolist()]
        fid, k = fid[order], k[order]
        n = np.array([len(r[2]) // 16 for r in rows], dtype=np.int64)  # the first column holds (x, y) float64
        arrays = tuple(piece_column(name, b"".join([r[2 + j] for r in rows])) for j, name in enumerate(names))
        return StoredPieces(fid, k, n, arrays)

    def load_heads(self, fids: Sequence[int]) -> list[ContourHead]:
        """The per-contour columns of contours by fid, without their rows (in the order given; unknown fids
        are skipped)."""
        return self._contours_by_fid(HEAD_COLUMNS, contour_head, fids)

    def dataset_heads(
        self, dataset: str
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The per-contour columns of every contour of a dataset, in fid order, as arrays: fid, elevation,
        vanishing scale (inf: never vanishes) and the (n, S) t tables."""
        rows = self._con().execute(
            f"SELECT {HEAD_COLUMNS} FROM contours WHERE dataset=? ORDER BY fid", (self._rows_of(dataset),)
        ).fetchall()
        fid = np.array([r[0] for r in rows], dtype=np.int64)
        elevation = np.array([r[1] for r in rows], dtype=np.float64)
        vanish = np.array([vanish_value(r[2]) for r in rows], dtype=np.float64)
        width = len(rows[0][3]) // 8 if rows else 1
        tables = np.frombuffer(b"".join([r[3] for r in rows]), dtype="<f8").reshape(len(rows), width)
        return fid, elevation, vanish, tables.astype(np.float64)

    def all_fids(self, dataset: str) -> list[int]:
        """Every contour fid of a dataset, in input order."""
        return [
            r[0]
            for r in self._con().execute(
                "SELECT fid FROM contours WHERE dataset=? ORDER BY fid", (self._rows_of(dataset),)
            )
        ]

    def elevations(self, dataset: str) -> NDArray[np.float64]:
        """The distinct elevations of a dataset's contours."""
        rows = self._con().execute(
            "SELECT DISTINCT elevation FROM contours WHERE dataset=?", (self._rows_of(dataset),)
        )
        return np.array([r[0] for r in rows], dtype=np.float64)

    def load(self, fids: Sequence[int], rows_id: str | None = None) -> list[ContourRecord]:
        """Decode contour rows by fid (in the order given; unknown fids are skipped, and with ``rows_id``
        (:meth:`rows_id`) those stored under another id)."""
        return self._contours_by_fid(CONTOUR_COLUMNS, contour_record, fids, rows_id)

    def _contours_by_fid(
        self, columns: str, decode: Callable[[Any], T], fids: Sequence[int], rows_id: str | None = None
    ) -> list[T]:
        """``decode`` of the ``columns`` (fid first) of each contour row by fid, in the order given (unknown fids
        are skipped, and with ``rows_id`` those of other rows); asked 500 fids at a time, below SQLite's limit on
        bound parameters."""
        out: dict[int, T] = {}
        con = self._con()
        ours = "" if rows_id is None else " AND dataset = ?"
        for i in range(0, len(fids), 500):
            chunk = list(fids[i : i + 500])
            marks = ",".join("?" * len(chunk))
            args = chunk if rows_id is None else [*chunk, rows_id]
            for r in con.execute(f"SELECT {columns} FROM contours WHERE fid IN ({marks}){ours}", args):
                out[r[0]] = decode(r)
        return [out[f] for f in fids if f in out]
