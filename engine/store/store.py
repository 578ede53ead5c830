"""The store: precomputed CCS rows, Sim(t) and t(scale) tables and dataset metadata in one SQLite file.

Persistence only: the rows arrive ready (reprojected, with their significance; :mod:`engine.serve.records`)
and leave decoded; what they mean is the serving layer's business.

- Contour extents sit in an R*Tree (EPSG:3857), so a tile looks up only the contours it touches.
- A dataset is written in **one transaction** (old rows out, new rows in, new ``data_version``): a build
  killed at any moment leaves the previous content as it was; SQLite's journal undoes the partial write.
- Each dataset records the content hash of its source and build parameters, so a changed source is rebuilt
  and an unchanged one is served at once after a restart.

The file's tables are :mod:`engine.store.schema`, its connections :mod:`engine.store.connection`, the records
:mod:`engine.store.records` and their bytes :mod:`engine.store.codec`; the builds recorded beside the
datasets are :mod:`engine.store.builds`.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Callable, Iterable, Sequence
from itertools import chain
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.errors import BuildCancelled, UnknownLayer
from engine.store.builds import BuildBook, forget_build, has_build, is_building
from engine.store.codec import (
    CONTOUR_COLUMNS,
    HEAD_COLUMNS,
    LABEL_COLUMNS,
    RowTally,
    contour_head,
    contour_pieces,
    contour_record,
    contour_row,
    dataset_info,
    dataset_row,
    label_row,
    piece_column,
    stored_labels,
    vanish_value,
)
from engine.store.issues import REPORTED_ISSUES, delete_issues, insert_issues, read_issues
from engine.store.records import (
    ContourHead,
    ContourRecord,
    DatasetInfo,
    LabelPlacer,
    NewContour,
    NewDataset,
    StoredLabels,
    StoredPieces,
)
from engine.store.schema import PIECE_KINDS


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
    Thread-safe: each thread gets its own connection.

    Parameters
    ----------
    path
        The file; created (with its directory) if missing.
    readonly
        Open without creating or migrating (for a second process that only reads).
    mmap_bytes
        Read up to this much of the file through memory mapping (SQLite's ``mmap_size``; 0: SQLite's default,
        none); see :class:`~engine.store.connection.StoreFile`.

    Raises
    ------
    StoreError
        The file is not a ccsm store, is of another format, or cannot be opened.
    """

    # -- datasets ----------------------------------------------------------------------------------------
    def dataset_ids(self) -> list[str]:
        """Ids of the stored (ready) datasets, sorted."""
        return [r[0] for r in self._con().execute("SELECT id FROM datasets ORDER BY id")]

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
        contours: Iterable[NewContour],
        progress: Callable[[int, int], None] | None = None,
        *,
        only_if_building: bool = False,
        labels: LabelPlacer | None = None,
    ) -> DatasetInfo:
        """Write a dataset, replacing any previous version, in one transaction.

        Inside the transaction the old rows are deleted and the new ones inserted as ``contours`` yields
        them (a generator keeps only one batch of rows in memory; the dataset's row, with its bounds and
        counts, goes in last). An exception (or a killed process) before COMMIT leaves the previous version
        untouched. With ``only_if_building`` the write happens only while the dataset's build is still
        recorded (checked inside the transaction), so a dataset deleted during its build never comes back:
        BuildCancelled is raised instead. ``progress`` gets (rows written, rows known so far). ``labels``, when
        given, is called after the rows and the dataset's row are in, and its anchors are written in the same
        transaction (with the new ``data_version``).
        """
        with self._write() as cur:
            if only_if_building and not is_building(cur, dataset):
                raise BuildCancelled(f"dataset {dataset!r} was deleted while it built")
            self._delete_rows(cur, dataset)
            counts = RowTally()
            step = 256
            for c in contours:
                cur.execute(
                    "INSERT INTO contours(dataset, contour_id, elevation, closed, grp, vanish_scale, "
                    "length_m, n_rows, n_input, base, top, original, original_w, t_at_scale, sim_t, sim, sig, "
                    "sig_top, sig_original) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    contour_row(dataset, c),
                )
                fid = cur.lastrowid
                cur.execute("INSERT INTO contour_rtree VALUES (?,?,?,?,?,?)", (fid, *c.box, dataset))
                if c.issues:
                    insert_issues(cur, dataset, int(fid or 0), c.issues)
                for kind, k, blobs, box in contour_pieces(c):
                    marks = ",".join("?" * len(blobs))
                    cur.execute(f"INSERT INTO {kind}_pieces VALUES (NULL,?,?,{marks})", (fid, k, *blobs))
                    cur.execute(f"INSERT INTO {kind}_piece_rtree VALUES (?,?,?,?,?,?)", (cur.lastrowid, *box, dataset))
                counts.add(c)
                if progress and counts.n % step == 0:
                    progress(counts.n, counts.n)
            if progress:
                progress(counts.n, counts.n)
            counter = int(cur.execute("SELECT value FROM store_meta WHERE key='version_counter'").fetchone()[0]) + 1
            cur.execute("UPDATE store_meta SET value=? WHERE key='version_counter'", (str(counter),))
            cur.execute(
                "INSERT INTO datasets VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                dataset_row(dataset, meta, counter, time.time(), counts),
            )
            if labels is not None:
                placed = labels()
                cur.execute("INSERT INTO labels VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", label_row(dataset, counter, placed))
                for label_fid, reason in placed.anchors.issues:
                    insert_issues(cur, dataset, label_fid, [("labels", reason)])
            forget_build(cur, dataset)
        return self.dataset(dataset)

    def labels(self, dataset: str) -> StoredLabels | None:
        """The label anchors stored with the dataset's current version, or None (none were placed at build)."""
        row = self._con().execute(f"SELECT {LABEL_COLUMNS} FROM labels WHERE dataset=?", (dataset,)).fetchone()
        return None if row is None else stored_labels(row)

    def contour_issues(self, dataset: str, limit: int = REPORTED_ISSUES) -> tuple[list[dict[str, Any]], int]:
        """The dataset's contours served without part of their build (``fid``, ``id``, ``step``, ``reason``;
        the first ``limit``) and how many there are."""
        return read_issues(self._con(), dataset, limit)

    @staticmethod
    def _delete_rows(cur: sqlite3.Cursor, dataset: str) -> None:
        cur.execute(
            "DELETE FROM contour_rtree WHERE fid IN (SELECT fid FROM contours WHERE dataset=?)", (dataset,)
        )
        for kind in PIECE_KINDS:
            pieces = f"SELECT piece FROM {kind}_pieces WHERE fid IN (SELECT fid FROM contours WHERE dataset=?)"
            cur.execute(f"DELETE FROM {kind}_piece_rtree WHERE piece IN ({pieces})", (dataset,))
            cur.execute(f"DELETE FROM {kind}_pieces WHERE piece IN ({pieces})", (dataset,))
        cur.execute("DELETE FROM contours WHERE dataset=?", (dataset,))
        cur.execute("DELETE FROM labels WHERE dataset=?", (dataset,))
        delete_issues(cur, dataset)
        cur.execute("DELETE FROM datasets WHERE id=?", (dataset,))

    def delete(self, dataset: str) -> bool:
        """Remove a dataset and its build status; True if it was stored."""
        with self._write() as cur:
            existed = cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
            self._delete_rows(cur, dataset)
            forget_build(cur, dataset)
        return existed

    def delete_any(self, dataset: str) -> bool:
        """Remove a dataset, stored or only building or failed; True if there was either."""
        with self._write() as cur:
            stored = cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
            build = has_build(cur, dataset)
            self._delete_rows(cur, dataset)
            forget_build(cur, dataset)
        return stored or build

    # -- contours ----------------------------------------------------------------------------------------
    def query(self, dataset: str, bounds_3857: Sequence[float]) -> list[int]:
        """fids of the dataset's contours whose extent meets an EPSG:3857 rectangle (R*Tree lookup)."""
        minx, miny, maxx, maxy = (float(v) for v in bounds_3857)
        # The dataset is an auxiliary column of the R*Tree: filtered after the spatial search, so the cost
        # follows the contours near the rectangle, not the size of the store.
        cur = self._con().execute(
            "SELECT fid FROM contour_rtree WHERE maxx >= ? AND minx <= ? AND maxy >= ? AND miny <= ? "
            "AND dataset = ? ORDER BY fid",
            (minx, maxx, miny, maxy, dataset),
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
        mine = fid_range if fid_range is not None else (dataset,)
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
        out: dict[int, ContourHead] = {}
        con = self._con()
        for i in range(0, len(fids), 500):
            chunk = list(fids[i : i + 500])
            marks = ",".join("?" * len(chunk))
            for r in con.execute(f"SELECT {HEAD_COLUMNS} FROM contours WHERE fid IN ({marks})", chunk):
                out[r[0]] = contour_head(r)
        return [out[f] for f in fids if f in out]

    def dataset_heads(
        self, dataset: str
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The per-contour columns of every contour of a dataset, in fid order, as arrays: fid, elevation,
        vanishing scale (inf: never vanishes) and the (n, S) t tables."""
        rows = self._con().execute(
            f"SELECT {HEAD_COLUMNS} FROM contours WHERE dataset=? ORDER BY fid", (dataset,)
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
            for r in self._con().execute("SELECT fid FROM contours WHERE dataset=? ORDER BY fid", (dataset,))
        ]

    def elevations(self, dataset: str) -> NDArray[np.float64]:
        """The distinct elevations of a dataset's contours."""
        rows = self._con().execute("SELECT DISTINCT elevation FROM contours WHERE dataset=?", (dataset,))
        return np.array([r[0] for r in rows], dtype=np.float64)

    def load(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decode contour rows by fid (in the order given; unknown fids are skipped)."""
        out: dict[int, ContourRecord] = {}
        con = self._con()
        for i in range(0, len(fids), 500):
            chunk = list(fids[i : i + 500])
            marks = ",".join("?" * len(chunk))
            for r in con.execute(f"SELECT {CONTOUR_COLUMNS} FROM contours WHERE fid IN ({marks})", chunk):
                out[r[0]] = contour_record(r)
        return [out[f] for f in fids if f in out]
