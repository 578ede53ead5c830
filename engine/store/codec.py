"""How the store's records become column values and back: little-endian blobs of float64 rows, float32
significance and int64 ids, JSON for texts and dicts, NULL for an infinite vanishing scale.

No SQL runs here (:mod:`engine.store.store` runs it): these functions only say what goes in a row's columns,
in the order its statement names them, and what a selected row decodes to. The bytes are the store's format
(:data:`~engine.store.schema.STORE_FORMAT`): a change here is a change of format.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from engine.store.records import (
    ContourHead,
    ContourRecord,
    DatasetInfo,
    LabelAnchors,
    NewContour,
    NewDataset,
    StoredLabels,
)
from engine.store.schema import PIECE_ROWS

#: Columns of a contour's row that :func:`contour_record` decodes, in its order.
CONTOUR_COLUMNS = (
    "fid, contour_id, elevation, closed, grp, vanish_scale, length_m, base, top, original, original_w, "
    "t_at_scale, sim_t, sim, sig, sig_top, sig_original"
)
#: Columns of a contour's row that :func:`contour_head` decodes, in its order.
HEAD_COLUMNS = "fid, elevation, vanish_scale, t_at_scale"
#: Columns of a dataset's labels that :func:`stored_labels` decodes, in its order.
LABEL_COLUMNS = "data_version, last_zoom, xy, angle, min_zoom, fid, rank, elevation, text, box_px"


class NamedColumns(Protocol):
    """A selected row whose columns are read by name (``sqlite3.Row``)."""

    def __getitem__(self, key: str) -> Any: ...  # noqa: D105


def f8_blob(a: NDArray[np.float64]) -> bytes:
    """Float64 values (any shape) as little-endian bytes."""
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


def f8_array(b: bytes, cols: int = 0) -> NDArray[np.float64]:
    """The float64 values of a blob: (n,) or, with ``cols``, (n, cols)."""
    a = np.frombuffer(b, dtype="<f8")
    return a.reshape(-1, cols) if cols else a


def f4_blob(a: NDArray[np.float32]) -> bytes:
    """Significance as little-endian float32 bytes."""
    return np.asarray(a, dtype="<f4").tobytes()


def f4_array(b: bytes) -> NDArray[np.float32]:
    """The float32 significance of a blob."""
    return np.frombuffer(b, dtype="<f4")


def vanish_column(scale: float) -> float | None:
    """A vanishing scale as stored: NULL for a contour that never vanishes (inf)."""
    return None if math.isinf(scale) else float(scale)


def vanish_value(column: float | None) -> float:
    """A stored vanishing scale (NULL: never, inf)."""
    return math.inf if column is None else float(column)


def piece_column(name: str, blob: bytes) -> NDArray[Any]:
    """A stored piece's column: float32 significance, else (n, 2) float64 rows."""
    return f4_array(blob) if name.startswith("sig") else f8_array(blob, 2)


def contour_row(dataset: str, c: NewContour) -> tuple[Any, ...]:
    """The values of a new contour's row, in the order of the ``contours`` table without its fid."""
    return (
        dataset,
        str(c.contour_id),
        float(c.elevation),
        int(c.closed),
        int(c.group),
        vanish_column(c.vanish_scale),
        float(c.length_m),
        len(c.base),
        int(c.n_input),
        f8_blob(c.base),
        f8_blob(c.top),
        f8_blob(c.original),
        f8_blob(c.original_w),
        f8_blob(c.t_at_scale),
        f8_blob(c.sim_t),
        f8_blob(c.sim),
        f4_blob(c.sig),
        f4_blob(c.sig_top),
        f4_blob(c.sig_original),
    )


def contour_record(r: Sequence[Any]) -> ContourRecord:
    """A contour selected by :data:`CONTOUR_COLUMNS`."""
    return ContourRecord(
        fid=r[0],
        contour_id=r[1],
        elevation=r[2],
        closed=bool(r[3]),
        group=r[4],
        vanish_scale=vanish_value(r[5]),
        length_m=r[6],
        base=f8_array(r[7], 2),
        top=f8_array(r[8], 2),
        original=f8_array(r[9], 2),
        original_w=f8_array(r[10], 2),
        t_at_scale=f8_array(r[11]),
        sim_t=f8_array(r[12]),
        sim=f8_array(r[13]),
        sig=f4_array(r[14]),
        sig_top=f4_array(r[15]),
        sig_original=f4_array(r[16]),
    )


def contour_head(r: Sequence[Any]) -> ContourHead:
    """A contour's head selected by :data:`HEAD_COLUMNS`."""
    return ContourHead(r[0], float(r[1]), vanish_value(r[2]), f8_array(r[3]))


def piece_rows(n: int, k: int) -> slice:
    """The rows of piece ``k`` of ``n`` rows (empty beyond the last piece)."""
    lo = k * PIECE_ROWS
    if k and lo >= n - 1:
        return slice(0, 0)
    return slice(lo, min(lo + PIECE_ROWS, n - 1) + 1)


def piece_count(n: int) -> int:
    """Pieces of ``n`` rows (one at least)."""
    return max(1, -(-(n - 1) // PIECE_ROWS))


def contour_pieces(c: NewContour) -> Iterator[tuple[str, int, list[bytes], tuple[float, float, float, float]]]:
    """The stored pieces of a contour: kind, k, the columns' bytes, and the box (minx, maxx, miny, maxy) of its
    rows."""
    for k in range(piece_count(len(c.base))):
        s = piece_rows(len(c.base), k)
        xy = np.concatenate([c.base[s], c.top[s]])
        sig = [f4_blob(c.sig[s]), f4_blob(c.sig_top[s])]
        yield "ccs", k, [f8_blob(c.base[s]), f8_blob(c.top[s]), *sig], _box(xy)
    for k in range(piece_count(len(c.original))):
        s = piece_rows(len(c.original), k)
        yield "original", k, [f8_blob(c.original[s]), f4_blob(c.sig_original[s])], _box(c.original[s])


def _box(xy: NDArray[np.float64]) -> tuple[float, float, float, float]:
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


class RowTally:
    """Counts and bounds of the rows written so far (a dataset's row is written after its contours)."""

    def __init__(self) -> None:
        self.n = 0
        self.closed = 0
        self.vertices = 0
        self.box = [math.inf, math.inf, -math.inf, -math.inf]  # minx, miny, maxx, maxy

    def add(self, c: NewContour) -> None:
        """Count one more contour."""
        self.n += 1
        self.closed += int(c.closed)
        self.vertices += c.n_input
        minx, maxx, miny, maxy = c.box
        self.box = [min(self.box[0], minx), min(self.box[1], miny), max(self.box[2], maxx), max(self.box[3], maxy)]

    def merge(self, other: RowTally) -> None:
        """Count another tally's contours too."""
        self.n += other.n
        self.closed += other.closed
        self.vertices += other.vertices
        self.box = [*map(min, self.box[:2], other.box[:2]), *map(max, self.box[2:], other.box[2:])]

    def bounds(self) -> tuple[float, float, float, float]:
        """(minx, miny, maxx, maxy) of every row, zeros when there is none."""
        return (0.0, 0.0, 0.0, 0.0) if self.n == 0 else (self.box[0], self.box[1], self.box[2], self.box[3])


def dataset_row(
    dataset: str, meta: NewDataset, data_version: int, built_at: float, rows: RowTally
) -> tuple[Any, ...]:
    """The values of a dataset's row, in the order of the ``datasets`` table (a build's row: its rows are stored
    under its id)."""
    return (
        dataset,
        meta.name,
        meta.source,
        meta.source_hash,
        json.dumps(meta.params, sort_keys=True, default=str),
        data_version,
        built_at,
        float(meta.build_seconds),
        meta.working_crs,
        meta.source_crs,
        None if meta.interval is None else float(meta.interval),
        *rows.bounds(),
        rows.n,
        rows.closed,
        rows.vertices,
        float(meta.source_scale),
        float(meta.target_scale),
        f8_blob(np.asarray(meta.ladder, dtype=np.float64)),
        json.dumps(meta.bad_features),
        dataset,
    )


def dataset_info(row: NamedColumns) -> DatasetInfo:
    """A dataset's row, selected whole."""
    return DatasetInfo(
        id=row["id"],
        name=row["name"],
        source=row["source"],
        source_hash=row["source_hash"],
        params=json.loads(row["params"]),
        data_version=int(row["data_version"]),
        built_at=float(row["built_at"]),
        build_seconds=float(row["build_seconds"]),
        working_crs=row["working_crs"],
        source_crs=row["source_crs"],
        interval=row["interval"],
        bounds_3857=(row["minx"], row["miny"], row["maxx"], row["maxy"]),
        n_contours=int(row["n_contours"]),
        n_closed=int(row["n_closed"]),
        n_vertices=int(row["n_vertices"]),
        source_scale=float(row["source_scale"]),
        target_scale=float(row["target_scale"]),
        ladder=f8_array(row["ladder"]),
        bad_features=json.loads(row["bad_features"]),
    )


def label_row(dataset: str, data_version: int, labels: StoredLabels) -> tuple[Any, ...]:
    """The values of a dataset's labels row, in the order of the ``labels`` table."""
    a = labels.anchors
    return (
        dataset,
        data_version,
        float(labels.last_zoom),
        len(a.fid),
        f8_blob(a.xy),
        f8_blob(a.angle),
        f8_blob(a.min_zoom),
        np.asarray(a.fid, dtype="<i8").tobytes(),
        np.asarray(a.rank, dtype="<i8").tobytes(),
        f8_blob(a.elevation),
        json.dumps(list(a.text)),
        f8_blob(a.box_px),
    )


def stored_labels(row: Sequence[Any]) -> StoredLabels:
    """A dataset's labels selected by :data:`LABEL_COLUMNS`."""
    anchors = LabelAnchors(
        xy=f8_array(row[2], 2),
        angle=f8_array(row[3]),
        min_zoom=f8_array(row[4]),
        fid=np.frombuffer(row[5], dtype="<i8"),
        rank=np.frombuffer(row[6], dtype="<i8"),
        elevation=f8_array(row[7]),
        text=list(json.loads(row[8])),
        box_px=f8_array(row[9], 2),
    )
    return StoredLabels(data_version=int(row[0]), last_zoom=float(row[1]), anchors=anchors)
